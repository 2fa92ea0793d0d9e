#pragma once
// Camera-style look-at poses for sensors and views (sensor frame: z forward, x right, y down).
#include "artisan/core/pose.hpp"

namespace artisan::sim {

/// T_world_camera at `eye` looking at `target`: z towards the target, x = z × up (right),
/// y = z × x (down). When the view is along `up`, x = z × `side` instead.
inline Transform look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ(),
                         const Eigen::Vector3d& side = Eigen::Vector3d::UnitY()) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = z.cross(up);
  if (x.norm() < 1e-9) x = z.cross(side);
  x.normalize();
  Transform T = Transform::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = z.cross(x);
  T.linear().col(2) = z;
  T.translation() = eye;
  return T;
}

}  // namespace artisan::sim
