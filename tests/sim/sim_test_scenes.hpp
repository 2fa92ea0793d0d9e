#pragma once
// Workcells built in code for the simulator tests (analytic scenes).
#include <string>
#include <vector>

#include "artisan/sim/shapes.hpp"
#include "artisan/sim/workcell.hpp"

namespace artisan::sim::test {

inline Body box_body(const std::string& name, const Eigen::Vector3d& size, const Transform& T_world_body, bool textured = true) {
  Body b;
  b.name = name;
  b.mesh = make_box(size);
  b.shape.kind = CollisionShape::Kind::box;
  b.shape.size = size;
  b.T_world_body = T_world_body;
  b.material.noise_texture = textured;
  b.material.texture_scale_m = 0.15f;
  return b;
}

inline Workcell cell_of(std::vector<Body> bodies) {
  Workcell c;
  c.source = "test scene";
  c.bodies = std::move(bodies);
  for (size_t i = 0; i < c.bodies.size(); ++i) c.bodies[i].instance_id = static_cast<int>(i) + 1;
  return c;
}

inline Transform at(double x, double y, double z) { return Transform(Eigen::Translation3d(x, y, z)); }

/// A wall whose camera-facing side is the plane z = d (camera at the origin looking along +z),
/// rotated by `angle` about the y axis through (0, 0, d).
inline Body wall_at(double d, double angle_rad = 0.0) {
  Transform T = Transform::Identity();
  T.linear() = Eigen::AngleAxisd(angle_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0, 0, d) + T.linear() * Eigen::Vector3d(0, 0, 0.1);
  return box_body("wall", {20, 20, 0.2}, T);
}

}  // namespace artisan::sim::test
