#include "convert.hpp"

#include <chrono>
#include <cmath>

#include "artisan/core/error.hpp"

namespace artisan::teleop {

int64_t now_utime() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

artisan::pose_t to_lcm(const Transform& T) {
  artisan::pose_t p;
  const Eigen::Quaterniond q(T.rotation());
  for (int k = 0; k < 3; ++k) p.position[k] = T.translation()[k];
  p.quaternion_xyzw[0] = q.x();
  p.quaternion_xyzw[1] = q.y();
  p.quaternion_xyzw[2] = q.z();
  p.quaternion_xyzw[3] = q.w();
  return p;
}

Transform from_lcm(const artisan::pose_t& p, const std::string& what) {
  const Eigen::Vector3d t(p.position[0], p.position[1], p.position[2]);
  const Eigen::Quaterniond q(p.quaternion_xyzw[3], p.quaternion_xyzw[0], p.quaternion_xyzw[1], p.quaternion_xyzw[2]);
  if (!t.allFinite() || !q.coeffs().allFinite()) throw Error(what + ": the pose is not finite");
  if (std::abs(q.norm() - 1.0) > 1e-3) throw Error(what + ": the quaternion is not unit (norm " + std::to_string(q.norm()) + ")");
  Transform T = Transform::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = t;
  return T;
}

artisan::scene_object_t to_lcm(const worldmodel::SceneObject& o) {
  artisan::scene_object_t m;
  m.object_id = o.object_id;
  m.version = o.version;
  m.path = o.path;
  m.kind = o.kind == worldmodel::SceneObject::Kind::environment ? "environment" : "object";
  m.model = o.model;
  m.pose = to_lcm(o.T_world_object);
  m.score = o.score;
  m.overlap = o.overlap;
  m.ambiguous = o.ambiguous;
  m.alternative_model = o.alternative_model;
  m.alternative_pose = to_lcm(o.T_world_alternative);
  m.mesh.hash = o.mesh_hash;
  m.mesh.n_vertices = int32_t(o.mesh->vertices.size());
  m.mesh.n_triangles = int32_t(o.mesh->faces.size());
  m.mesh.n_bytes = 0;
  m.margin = o.margin_m;
  for (const auto& g : o.T_world_grasps) m.grasps.push_back(to_lcm(g));
  m.n_grasps = int32_t(m.grasps.size());
  m.attached_to = o.attached_to;
  m.status = o.status;
  return m;
}

artisan::robot_state_t to_lcm(const worldmodel::SceneRobot& r) {
  artisan::robot_state_t m;
  m.object_id = r.object_id;
  m.version = r.version;
  m.name = r.name;
  m.path = r.path;
  m.root_pose = to_lcm(r.T_world_root);
  for (const auto& name : r.model->joint_names()) {
    m.joint_names.push_back(name);
    m.joint_values.push_back(r.joints.at(name));
  }
  m.n_joints = int32_t(m.joint_names.size());
  for (const auto& [link, T] : r.T_world_links) {
    m.link_names.push_back(link);
    m.link_poses.push_back(to_lcm(T));
  }
  m.n_links = int32_t(m.link_names.size());
  return m;
}

worldmodel::QueryShape from_lcm(const artisan::shape_t& s, const std::vector<Eigen::Vector3f>* hull_points) {
  using worldmodel::QueryShape;
  QueryShape q;
  q.name = s.name;
  const std::string what = "shape '" + s.name + "'";
  q.T_world_shape = from_lcm(s.pose, what);
  switch (s.kind) {
    case artisan::shape_t::BOX:
      q.kind = QueryShape::Kind::box;
      q.size = Eigen::Vector3d(s.dims[0], s.dims[1], s.dims[2]);
      break;
    case artisan::shape_t::SPHERE:
      q.kind = QueryShape::Kind::sphere;
      q.radius_m = s.dims[0];
      break;
    case artisan::shape_t::CYLINDER:
    case artisan::shape_t::CAPSULE:
      q.kind = s.kind == artisan::shape_t::CYLINDER ? QueryShape::Kind::cylinder : QueryShape::Kind::capsule;
      q.radius_m = s.dims[0];
      q.length_m = s.dims[1];
      break;
    case artisan::shape_t::CONVEX_MESH:
      if (!hull_points) throw Error(what + ": no scene mesh has hash '" + s.mesh_hash + "'");
      q.kind = QueryShape::Kind::convex_hull;
      q.points = *hull_points;
      break;
    default: throw Error(what + ": unknown kind " + std::to_string(int(s.kind)));
  }
  return q;
}

worldmodel::AllowedPair from_lcm(const artisan::allowed_pair_t& a) { return {a.shape, a.object_id}; }

}  // namespace artisan::teleop
