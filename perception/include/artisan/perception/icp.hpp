#pragma once
// Point-to-plane ICP (Chen & Medioni 1992; closest points as in Besl & McKay 1992) with
// correspondence rejection by distance and normal compatibility and a Huber kernel, usable
// alone from a given initial pose.
#include <cstddef>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/kdtree.hpp"

namespace artisan {

struct IcpSettings {
  int max_iterations = 60;                      ///< [1]
  double max_correspondence_distance_m = 0.01;  ///< [m] farther pairs are rejected
  double max_normal_angle_deg = 45.0;           ///< [deg] pairs whose normals differ more are rejected
  double huber_delta_m = 0.0005;                ///< [m] residual where the Huber kernel turns linear
  double convergence_rotation_rad = 1e-5;       ///< [rad] stop when an update rotates less ...
  double convergence_translation_m = 1e-6;      ///< [m] ... and translates less than this
  size_t max_source_points = 4000;              ///< [1] source points used (evenly subsampled)
};

struct IcpResult {
  Transform T_target_source = Transform::Identity();
  bool converged = false;
  int iterations = 0;
  double rmse_m = 0.0;             ///< [m] point-to-plane RMS residual of the inliers
  size_t inliers = 0;              ///< source samples with an accepted correspondence
  size_t samples = 0;              ///< source samples used
  double overlap_fraction = 0.0;   ///< inliers / samples
};

/// Aligns `source` (points with normals) to `target` starting from T_target_source_init.
/// `target_tree` indexes target.points. Throws artisan::Error when either cloud lacks normals
/// or points, or the settings are out of range.
IcpResult icp_point_to_plane(const PointCloud& source, const PointCloud& target, const KdTree3& target_tree,
                             const Transform& T_target_source_init, const IcpSettings& settings = {});

/// Vertices and normals of a mesh (normals computed when missing).
PointCloud oriented_points(const TriangleMesh& mesh);

}  // namespace artisan
