#pragma once
// Conversions between the world model's types and the generated LCM types, with validation of
// what clients send.
#include <string>
#include <vector>

#include "artisan/allowed_pair_t.hpp"
#include "artisan/pose_t.hpp"
#include "artisan/robot_state_t.hpp"
#include "artisan/scene_object_t.hpp"
#include "artisan/shape_t.hpp"
#include "artisan/worldmodel/collision_scene.hpp"
#include "artisan/worldmodel/world_model.hpp"

namespace artisan::teleop {

artisan::pose_t to_lcm(const Transform& T);
/// Throws artisan::Error (naming `what`) when the pose is not finite or the quaternion not unit.
Transform from_lcm(const artisan::pose_t& p, const std::string& what);
artisan::scene_object_t to_lcm(const worldmodel::SceneObject& o);
artisan::robot_state_t to_lcm(const worldmodel::SceneRobot& r);
/// `hull_points(hash)` gives the vertices of a scene mesh for CONVEX_MESH shapes (throws when
/// unknown). Throws artisan::Error naming the shape for anything malformed.
worldmodel::QueryShape from_lcm(const artisan::shape_t& s, const std::vector<Eigen::Vector3f>* hull_points);
worldmodel::AllowedPair from_lcm(const artisan::allowed_pair_t& a);
int64_t now_utime();

}  // namespace artisan::teleop
