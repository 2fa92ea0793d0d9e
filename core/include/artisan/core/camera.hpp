#pragma once
// Pinhole camera intrinsics. The camera frame is x right, y down, z forward (optical axis);
// pixel (u, v) has its origin at the centre of the top-left pixel.
#include <optional>

#include <Eigen/Core>

namespace artisan {

struct PinholeCamera {
  int width = 0;     ///< image width [pixels]
  int height = 0;    ///< image height [pixels]
  double fx = 0.0;   ///< focal length along u [pixels]
  double fy = 0.0;   ///< focal length along v [pixels]
  double cx = 0.0;   ///< principal point u [pixels]
  double cy = 0.0;   ///< principal point v [pixels]

  /// Pixel coordinates of a point in the camera frame; nullopt when z <= 0.
  std::optional<Eigen::Vector2d> project(const Eigen::Vector3d& p_camera) const;
  /// The point at depth z (along the optical axis) seen at pixel (u, v).
  Eigen::Vector3d unproject(const Eigen::Vector2d& uv, double z) const;
  /// Throws artisan::Error if sizes or focal lengths are not positive and finite.
  void validate() const;
};

}  // namespace artisan
