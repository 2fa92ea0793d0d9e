#pragma once
// Private: pose proposals for parts made mostly of one cylinder (a straight pipe), from the
// axes of the scene's cylindrical surface. Neither spin images nor point-pair voting place
// them: every point of a cylinder's body has the same spin image, and every pair of its points
// the same feature as many others along it (the voting table leaves those crowded cells out),
// so only the rims fix a pose, and a rim is often hidden. The scene's cylinders of the part's
// radius are found instead (each point's neighbourhood: normals across one direction, and the
// points a radius behind them on one line, the axis), and the part is put on each axis at
// every shift (and turn, when it is not round) that overlaps the seen extent; recognition
// scores those poses like its other hypotheses and verifies the best.
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/kdtree.hpp"

namespace artisan::detail {

/// The cylinder a model is mostly made of, in the model frame.
struct ModelCylinder {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();      ///< on the axis
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  ///< of the axis, unit
  double radius = 0;       ///< [m] of the outer surface
  double start = 0, end = 0;  ///< [m] the model's extent along the axis, from `point`
  double share = 0;        ///< [1] of the model's points on cylinders about the axis (outer and inner)
  bool round = false;      ///< turning the model about the axis maps its surface onto itself
};

/// The cylinder about the axis through `axis_point` along `axis_direction` (a turn axis of the
/// model), when at least `min_share` of the model's points lie on cylinders about it (normal
/// across the axis, through it) and most of its outward-facing ones on one radius; else none.
/// `res` [m] is the points' spacing (the tolerances are fractions of it).
std::optional<ModelCylinder> model_cylinder(const PointCloud& model, const Eigen::Vector3d& axis_point, const Eigen::Vector3d& axis_direction,
                                            double res, double min_share);

/// The round parts of a model that is not mostly one cylinder (a flange's neck): cylinders about
/// the axis (outward normals, one radius within a spacing) holding at least `min_share` of its
/// points, at least 3 spacings in radius and at least their radius long (a shorter band, such as
/// a flange's rim, fixes no axis where it is seen), about which the whole model is round; their
/// start and end are the part's extent. Largest first.
std::vector<ModelCylinder> model_round_parts(const PointCloud& model, const Eigen::Vector3d& axis_point, const Eigen::Vector3d& axis_direction,
                                             double res, double min_share);

/// Whether turning the model about the axis maps its surface onto itself (within 1.5 `res`).
bool round_about(const PointCloud& model, const Eigen::Vector3d& axis_point, const Eigen::Vector3d& axis_direction, double res);

/// The axis of a cylindrical piece of the scene's surface.
struct SceneAxis {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();      ///< on the axis, at the middle of the seen extent
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  ///< unit
  double start = 0, end = 0;  ///< [m] the seen surface's extent along the axis, from `point`
  size_t points = 0;          ///< scene points on it
};

/// The axes of the scene's cylindrical surfaces of `radius` [m] (outward normals, as a sensor
/// sees a cylinder's outside), largest first, each with at least `min_points` scene points.
/// Points with `ignore` set (the planes that do not vote: background planes, and support planes
/// with no_votes_on_support) are left out. `res` [m]: the scene's spacing.
std::vector<SceneAxis> scene_axes(const PointCloud& scene, const KdTree3& scene_tree, double radius, double res, const std::vector<char>& ignore,
                                  size_t min_points);

/// Poses that put the model's cylinder on the scene axis, both ways along it, at shifts `step`
/// [m] apart over every placement whose extent overlaps the seen one, and (unless the model is
/// round) at `turns` turns about the axis.
std::vector<Transform> poses_on_axis(const ModelCylinder& cylinder, const SceneAxis& axis, double step, int turns);

}  // namespace artisan::detail
