#include "artisan/worldmodel/robot_model.hpp"

#include <urdf_parser/urdf_parser.h>

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

fs::path resolve(const std::string& uri, const fs::path& base, const std::vector<fs::path>& package_paths, const fs::path& file) {
  const std::string prefix = "package://";
  if (uri.rfind(prefix, 0) != 0) {
    const fs::path p = uri.rfind("file://", 0) == 0 ? fs::path(uri.substr(7)) : fs::path(uri);
    return p.is_absolute() ? p : base / p;
  }
  for (const auto& root : package_paths)
    if (fs::exists(root / uri.substr(prefix.size()))) return root / uri.substr(prefix.size());
  throw Error(file.string() + ": cannot find '" + uri + "' in the package paths");
}

// Points whose convex hull is the geometry, in the geometry's frame.
std::vector<Eigen::Vector3f> hull_points(const urdf::Geometry& g, const fs::path& base, const std::vector<fs::path>& packages,
                                         const fs::path& file) {
  std::vector<Eigen::Vector3f> pts;
  switch (g.type) {
    case urdf::Geometry::BOX: {
      const auto& d = static_cast<const urdf::Box&>(g).dim;
      for (int i = 0; i < 8; ++i)
        pts.emplace_back(float((i & 1 ? 0.5 : -0.5) * d.x), float((i & 2 ? 0.5 : -0.5) * d.y), float((i & 4 ? 0.5 : -0.5) * d.z));
      break;
    }
    case urdf::Geometry::CYLINDER:
    case urdf::Geometry::SPHERE: {
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
      break;
    }
    case urdf::Geometry::MESH: {
      const auto& m = static_cast<const urdf::Mesh&>(g);
      const auto mesh = io::read_mesh(resolve(m.filename, base, packages, file));
      for (const auto& v : mesh.vertices) pts.emplace_back(v.cwiseProduct(Eigen::Vector3f(float(m.scale.x), float(m.scale.y), float(m.scale.z))));
      break;
    }
  }
  return pts;
}

}  // namespace

RobotModel RobotModel::load(const fs::path& urdf_file, const std::vector<fs::path>& package_paths) {
  std::ifstream in(urdf_file);
  if (!in) throw Error(urdf_file.string() + ": cannot read the URDF");
  std::stringstream text;
  text << in.rdbuf();
  const auto model = urdf::parseURDF(text.str());
  if (!model || !model->getRoot()) throw Error(urdf_file.string() + ": not a valid URDF");
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
        default: throw Error(urdf_file.string() + ": joint '" + cj->name + "' is of a kind not supported (floating or planar)");
      }
      if (j.type != Joint::Type::fixed && j.axis.norm() == 0) throw Error(urdf_file.string() + ": joint '" + cj->name + "' has no axis");
      if (j.type != Joint::Type::fixed) j.axis.normalize();
      if (cj->limits) j.lower = cj->limits->lower, j.upper = cj->limits->upper;
      r.joints_.push_back(j);
    }
    for (const auto& c : link->child_links) stack.push_back(c);
  }
  for (const auto& [name, link] : model->links_) {
    std::vector<Eigen::Vector3f> pts;
    for (const auto& c : link->collision_array) {
      if (!c || !c->geometry) continue;
      const Eigen::Matrix4f T = from_urdf(c->origin).matrix().cast<float>();
      for (const auto& p : hull_points(*c->geometry, urdf_file.parent_path(), package_paths, urdf_file))
        pts.push_back((T * p.homogeneous()).head<3>());
    }
    if (pts.size() >= 4) r.hulls_[name] = std::move(pts);
  }
  return r;
}

std::vector<std::string> RobotModel::joint_names() const {
  std::vector<std::string> names;
  for (const auto& j : joints_)
    if (j.type != Joint::Type::fixed) names.push_back(j.name);
  return names;
}

std::map<std::string, Transform> RobotModel::link_poses(const std::map<std::string, double>& joints, const Transform& T_world_root) const {
  std::set<std::string> known;
  for (const auto& j : joints_) known.insert(j.name);
  for (const auto& [name, value] : joints) {
    if (!known.count(name)) throw Error("robot '" + name_ + "' has no joint '" + name + "'");
    if (!std::isfinite(value)) throw Error("robot '" + name_ + "': joint '" + name + "' is not finite");
  }
  std::map<std::string, Transform> poses = {{root_, T_world_root}};
  for (const auto& j : joints_) {
    const auto it = joints.find(j.name);
    const double q = it == joints.end() ? 0.0 : it->second;
    if ((j.type == Joint::Type::revolute || j.type == Joint::Type::prismatic) && (q < j.lower - 1e-9 || q > j.upper + 1e-9))
      throw Error("robot '" + name_ + "': joint '" + j.name + "' at " + std::to_string(q) + " is beyond its limits [" + std::to_string(j.lower) +
                  ", " + std::to_string(j.upper) + "]");
    Transform motion = Transform::Identity();
    if (j.type == Joint::Type::revolute || j.type == Joint::Type::continuous) motion.linear() = Eigen::AngleAxisd(q, j.axis).toRotationMatrix();
    if (j.type == Joint::Type::prismatic) motion.translation() = q * j.axis;
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
