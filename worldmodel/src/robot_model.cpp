#include "artisan/worldmodel/robot_model.hpp"

#include <LinearMath/btConvexHullComputer.h>
#include <urdf_parser/urdf_parser.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_io.hpp"

namespace artisan::worldmodel {
namespace {

namespace fs = std::filesystem;

Transform from_urdf(const urdf::Pose& p) {
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  T.linear() = Eigen::Quaterniond(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z).normalized().toRotationMatrix();
  return T;
}

std::string format_value(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

urdf::ModelInterfaceSharedPtr parse_model(const std::string& text, const std::string& source) {
  urdf::ModelInterfaceSharedPtr model;
  try {
    model = urdf::parseURDF(text);
  } catch (const std::exception& e) {
    throw Error(source + ": not a valid URDF (" + e.what() + ")");
  }
  if (!model || !model->getRoot()) throw Error(source + ": not a valid URDF");
  return model;
}

// Links in a fixed order (by name), so every traversal lists meshes the same way.
std::vector<urdf::LinkSharedPtr> links_of(const urdf::ModelInterface& model) {
  std::vector<urdf::LinkSharedPtr> out;
  for (const auto& [name, link] : model.links_) out.push_back(link);
  return out;
}

// The convex hull of `points` as a closed triangle mesh, faces counter-clockwise seen from outside.
TriangleMesh hull_mesh(const std::vector<Eigen::Vector3f>& points) {
  TriangleMesh m;
  if (points.size() < 4) return m;
  btConvexHullComputer hull;
  hull.compute(points.front().data(), sizeof(Eigen::Vector3f), int(points.size()), 0, 0);
  for (int i = 0; i < hull.vertices.size(); ++i) m.vertices.push_back(points[size_t(hull.original_vertex_index[i])]);
  Eigen::Vector3f centre = Eigen::Vector3f::Zero();
  for (const auto& v : m.vertices) centre += v;
  centre /= float(std::max<size_t>(1, m.vertices.size()));
  for (int f = 0; f < hull.faces.size(); ++f) {
    const auto* first = &hull.edges[hull.faces[f]];
    std::vector<int> ring;
    for (const auto* e = first;;) {
      ring.push_back(e->getTargetVertex());
      e = e->getNextEdgeOfFace();
      if (e == first || ring.size() > size_t(hull.vertices.size())) break;
    }
    for (size_t k = 1; k + 1 < ring.size(); ++k) {
      Eigen::Vector3i t(ring[0], ring[k], ring[k + 1]);
      const Eigen::Vector3f a = m.vertices[size_t(t[0])], b = m.vertices[size_t(t[1])], c = m.vertices[size_t(t[2])];
      if ((b - a).cross(c - a).dot(a - centre) < 0) std::swap(t[1], t[2]);
      m.faces.push_back(t);
    }
  }
  return m;
}

// Points whose convex hull is a box, cylinder or sphere, in the geometry's frame.
std::vector<Eigen::Vector3f> primitive_points(const urdf::Geometry& g) {
  std::vector<Eigen::Vector3f> pts;
  if (g.type == urdf::Geometry::BOX) {
    const auto& d = static_cast<const urdf::Box&>(g).dim;
    for (int i = 0; i < 8; ++i)
      pts.emplace_back(float((i & 1 ? 0.5 : -0.5) * d.x), float((i & 2 ? 0.5 : -0.5) * d.y), float((i & 4 ? 0.5 : -0.5) * d.z));
    return pts;
  }
  const bool sphere = g.type == urdf::Geometry::SPHERE;
  const double r = sphere ? static_cast<const urdf::Sphere&>(g).radius : static_cast<const urdf::Cylinder&>(g).radius;
  const double h = sphere ? 0 : static_cast<const urdf::Cylinder&>(g).length / 2;
  for (int k = 0; k < 24; ++k) {
    const double a = 2 * M_PI * k / 24;
    if (sphere)
      for (int j = -3; j <= 3; ++j) {
        const double e = M_PI / 2 * j / 4;
        pts.emplace_back(float(r * std::cos(e) * std::cos(a)), float(r * std::cos(e) * std::sin(a)), float(r * std::sin(e)));
      }
    else
      for (double z : {-h, h}) pts.emplace_back(float(r * std::cos(a)), float(r * std::sin(a)), float(z));
  }
  if (sphere) pts.emplace_back(0.f, 0.f, float(r)), pts.emplace_back(0.f, 0.f, float(-r));
  return pts;
}

}  // namespace

std::vector<Eigen::Vector3f> convex_hull_vertices(const std::vector<Eigen::Vector3f>& points) {
  if (points.size() < 4) return points;
  return hull_mesh(points).vertices;
}

fs::path RobotModel::resolve_uri(const std::string& uri, const fs::path& urdf_file, const std::vector<fs::path>& package_paths) {
  const std::string prefix = "package://";
  if (uri.rfind(prefix, 0) != 0) {
    const fs::path p = uri.rfind("file://", 0) == 0 ? fs::path(uri.substr(7)) : fs::path(uri);
    const fs::path full = p.is_absolute() ? p : urdf_file.parent_path() / p;
    if (!fs::exists(full)) throw Error(urdf_file.string() + ": the mesh '" + uri + "' is not at " + full.string());
    return full;
  }
  for (const auto& root : package_paths)
    if (fs::exists(root / uri.substr(prefix.size()))) return root / uri.substr(prefix.size());
  std::string searched;
  for (const auto& root : package_paths) searched += (searched.empty() ? "" : ", ") + root.string();
  throw Error(urdf_file.string() + ": cannot find '" + uri + "' in the package paths (" + (searched.empty() ? "none given" : searched) + ")");
}

RobotModel RobotModel::load(const fs::path& urdf_file, const std::vector<fs::path>& package_paths) {
  std::ifstream in(urdf_file);
  if (!in) throw Error(urdf_file.string() + ": cannot read the URDF");
  std::stringstream text;
  text << in.rdbuf();
  return parse(text.str(), urdf_file.string(),
               [&](const std::string& uri) { return io::read_mesh(resolve_uri(uri, urdf_file, package_paths)); });
}

std::vector<std::string> RobotModel::collision_mesh_uris(const std::string& urdf_text, const std::string& source) {
  const auto model = parse_model(urdf_text, source);
  std::vector<std::string> uris;
  std::set<std::string> seen;
  for (const auto& link : links_of(*model))
    for (const auto& c : link->collision_array)
      if (c && c->geometry && c->geometry->type == urdf::Geometry::MESH) {
        const auto& uri = static_cast<const urdf::Mesh&>(*c->geometry).filename;
        if (seen.insert(uri).second) uris.push_back(uri);
      }
  return uris;
}

RobotModel RobotModel::parse(const std::string& urdf_text, const std::string& source, const MeshSource& meshes) {
  const auto model = parse_model(urdf_text, source);
  RobotModel r;
  r.name_ = model->getName();
  r.root_ = model->getRoot()->name;
  // Joints parents first: walk the tree from the root.
  std::vector<urdf::LinkConstSharedPtr> stack = {model->getRoot()};
  while (!stack.empty()) {
    const auto link = stack.back();
    stack.pop_back();
    for (const auto& cj : link->child_joints) {
      Joint j;
      j.name = cj->name;
      j.parent = cj->parent_link_name;
      j.child = cj->child_link_name;
      j.T_parent_joint = from_urdf(cj->parent_to_joint_origin_transform);
      j.axis = Eigen::Vector3d(cj->axis.x, cj->axis.y, cj->axis.z);
      switch (cj->type) {
        case urdf::Joint::REVOLUTE: j.type = Joint::Type::revolute; break;
        case urdf::Joint::CONTINUOUS: j.type = Joint::Type::continuous; break;
        case urdf::Joint::PRISMATIC: j.type = Joint::Type::prismatic; break;
        case urdf::Joint::FIXED: j.type = Joint::Type::fixed; break;
        default: throw Error(source + ": joint '" + cj->name + "' is of a kind not supported (floating or planar)");
      }
      if (j.movable() && j.axis.norm() == 0) throw Error(source + ": joint '" + cj->name + "' has no axis");
      if (j.movable()) j.axis.normalize();
      if (cj->limits) j.lower = cj->limits->lower, j.upper = cj->limits->upper, j.effort = cj->limits->effort, j.velocity = cj->limits->velocity;
      if (j.type == Joint::Type::continuous) j.lower = -INFINITY, j.upper = INFINITY;
      r.joints_.push_back(j);
    }
    for (const auto& c : link->child_links) stack.push_back(c);
  }
  for (const auto& link : links_of(*model)) {
    TriangleMesh geometry;
    for (const auto& c : link->collision_array) {
      if (!c || !c->geometry) continue;
      TriangleMesh part;
      if (c->geometry->type == urdf::Geometry::MESH) {
        const auto& m = static_cast<const urdf::Mesh&>(*c->geometry);
        part = meshes(m.filename);
        part.normals.clear(), part.uv.clear(), part.colors.clear();
        part.texture = {};
        const Eigen::Vector3f scale(float(m.scale.x), float(m.scale.y), float(m.scale.z));
        for (auto& v : part.vertices) v = v.cwiseProduct(scale);
      } else {
        part = hull_mesh(primitive_points(*c->geometry));
      }
      part.transform(from_urdf(c->origin));
      geometry.append(part);
    }
    if (geometry.vertices.size() < 4) continue;
    for (const auto& v : geometry.vertices)
      if (!v.allFinite()) throw Error(source + ": the collision geometry of link '" + link->name + "' has a non-finite vertex");
    TriangleMesh hull = hull_mesh(geometry.vertices);
    if (hull.vertices.size() < 4) continue;  // flat: nothing a hull can hold
    r.hulls_[link->name] = std::move(hull.vertices);
    r.meshes_[link->name] = std::make_shared<const TriangleMesh>(std::move(geometry));
  }
  return r;
}

std::vector<std::string> RobotModel::joint_names() const {
  std::vector<std::string> names;
  for (const auto& j : joints_)
    if (j.movable()) names.push_back(j.name);
  return names;
}

std::map<std::string, double> RobotModel::default_joints() const {
  std::map<std::string, double> q;
  for (const auto& j : joints_)
    if (j.movable()) q[j.name] = std::clamp(0.0, std::min(j.lower, j.upper), std::max(j.lower, j.upper));
  return q;
}

void RobotModel::check_joints(const std::map<std::string, double>& joints) const {
  for (const auto& [name, value] : joints) {
    const auto it = std::find_if(joints_.begin(), joints_.end(), [&](const Joint& j) { return j.movable() && j.name == name; });
    if (it == joints_.end()) {
      std::string names;
      for (const auto& n : joint_names()) names += (names.empty() ? "" : ", ") + n;
      throw Error("robot '" + name_ + "' has no joint '" + name + "' (its joints: " + names + ")");
    }
    if (!std::isfinite(value)) throw Error("robot '" + name_ + "': joint '" + name + "' is not finite (" + format_value(value) + ")");
    if ((it->type == Joint::Type::revolute || it->type == Joint::Type::prismatic) && (value < it->lower - 1e-9 || value > it->upper + 1e-9))
      throw Error("robot '" + name_ + "': joint '" + name + "' at " + format_value(value) + " is beyond its limits [" + format_value(it->lower) +
                  ", " + format_value(it->upper) + "]");
  }
}

std::map<std::string, Transform> RobotModel::link_poses(const std::map<std::string, double>& joints, const Transform& T_world_root) const {
  check_joints(joints);
  const auto defaults = default_joints();
  std::map<std::string, Transform> poses = {{root_, T_world_root}};
  for (const auto& j : joints_) {
    Transform motion = Transform::Identity();
    if (j.movable()) {
      const auto it = joints.find(j.name);
      const double q = it == joints.end() ? defaults.at(j.name) : it->second;
      if (j.type == Joint::Type::prismatic) motion.translation() = q * j.axis;
      else motion.linear() = Eigen::AngleAxisd(q, j.axis).toRotationMatrix();
    }
    poses[j.child] = poses.at(j.parent) * j.T_parent_joint * motion;
  }
  return poses;
}

std::vector<QueryShape> RobotModel::collision_shapes(const std::map<std::string, double>& joints, const Transform& T_world_root) const {
  const auto poses = link_poses(joints, T_world_root);
  std::vector<QueryShape> shapes;
  for (const auto& [link, pts] : hulls_) {
    QueryShape s;
    s.name = name_ + "/" + link;
    s.kind = QueryShape::Kind::convex_hull;
    s.points = pts;
    s.T_world_shape = poses.at(link);
    shapes.push_back(std::move(s));
  }
  return shapes;
}

}  // namespace artisan::worldmodel
