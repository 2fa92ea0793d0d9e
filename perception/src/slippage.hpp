#pragma once
// Private: whether a model's surface can slide along itself (Gelfand et al., "Geometrically
// stable sampling for the ICP algorithm", 3DIM 2003): the rigid motions that move every point
// along its tangent plane, to first order, leave a point-to-plane fit no hold on the pose. A
// pipe slides along its axis, an elbow about its bend; a flange turns about its axis too, but
// that turn maps it onto itself (a symmetry, no other pose); a tee or a valve does not slide.
#include <cstddef>
#include <optional>

#include <Eigen/Geometry>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/kdtree.hpp"

namespace artisan::detail {

/// The share of every `step`-th model point that `motion` moves more than `tolerance` [m] from
/// the model's surface (its points, which `tree` indexes): 0 when the motion maps the surface
/// onto itself (a symmetry).
double share_moved_off(const PointCloud& model, const KdTree3& tree, const Eigen::Isometry3f& motion, double tolerance, size_t step = 1);

/// A motion that moves a model's surface along itself: a shift along an axis (a pipe along its
/// own) or a turn about one (an elbow about its bend), measured by how far it moves the surface.
struct Slide {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();       ///< on the axis [m]
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  ///< of the axis, unit
  double radius = 0;  ///< [m] a turn's: the points' RMS distance from its axis; 0: a shift
  double extent = 0;  ///< [m] how far the surface reaches along the motion (a pipe's length, an elbow's arc at `radius`)
  /// The motion by `s` [m]: a shift by s, or a turn by s / radius.
  Transform by(double s) const;
};

/// The slide along the axis of a straight model (`extent` its length along it).
Slide shift_along(const Eigen::Vector3d& point, const Eigen::Vector3d& direction, double extent);

/// A motion that moves the model's surface along itself without being a symmetry of it, or none.
/// The motions: the eigenvectors of the point-to-plane normal equations' 6x6 matrix (rotations
/// about the centroid in units of the points' RMS distance from it) whose eigenvalue is at most
/// `max_ratio` of the largest. Each is applied until some point has moved 3 `res`; it is a
/// symmetry when then at most 1% of the points lie more than 1.5 `res` from the model's surface.
/// The first that is none is returned as a turn about its screw axis (its pitch dropped), or as
/// a shift when it turns the points by less than a twentieth of how far it shifts them.
std::optional<Slide> slide_along_itself(const PointCloud& model, double res, double max_ratio = 0.1);

}  // namespace artisan::detail
