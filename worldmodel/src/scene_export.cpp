#include "artisan/worldmodel/scene_export.hpp"

#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <sstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"
#include "artisan/core/io/mesh_io.hpp"

namespace artisan::worldmodel {
namespace {

namespace fs = std::filesystem;

// A name tools accept (letters, digits, '_'), unique within the scene.
std::string link_name(const SceneObject& o, std::set<std::string>& used) {
  std::string base = o.kind == SceneObject::Kind::environment ? "environment" : o.path.substr(o.path.rfind('/') + 1);
  for (char& c : base)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  std::string name = base;
  for (int k = 2; used.count(name); ++k) name = base + "_" + std::to_string(k);
  used.insert(name);
  return name;
}

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

// Fixed-axis roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll)), as URDF and SDF use.
Eigen::Vector3d rpy(const Eigen::Matrix3d& R) {
  const double pitch = std::asin(std::clamp(-R(2, 0), -1.0, 1.0));
  double roll, yaw;
  if (std::abs(std::cos(pitch)) > 1e-9) {
    roll = std::atan2(R(2, 1), R(2, 2));
    yaw = std::atan2(R(1, 0), R(0, 0));
  } else {  // gimbal lock: put it all in yaw
    roll = 0;
    yaw = std::atan2(-R(0, 1), R(1, 1));
  }
  return {roll, pitch, yaw};
}

std::string sanitized(std::string name) {
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return name;
}

std::string xyz(const Eigen::Vector3d& v) { return num(v.x()) + " " + num(v.y()) + " " + num(v.z()); }

// URDF: the robot's own tree with its names prefixed ("ur5_shoulder_link"), hung from the scene's
// "world" by a fixed joint at T_world_root; each link's collision geometry as one STL (link frame),
// also its visual. Returns the XML; `written` gains the meshes.
std::string robot_urdf(const SceneRobot& r, const std::string& prefix, const fs::path& dir, std::vector<fs::path>& written) {
  std::ostringstream xml;
  const auto& m = *r.model;
  xml << "  <!-- robot " << r.path << " (version " << r.version << "), current joint values:";
  for (const auto& name : m.joint_names()) xml << " " << name << "=" << num(r.joints.at(name));
  xml << " -->\n";
  std::set<std::string> links = {m.root_link()};
  for (const auto& j : m.joints()) links.insert(j.child);
  for (const auto& link : links) {
    xml << "  <link name=\"" << prefix << link << "\"";
    const auto it = m.link_meshes().find(link);
    if (it == m.link_meshes().end()) {
      xml << "/>\n";
      continue;
    }
    const std::string mesh_file = "meshes/" + prefix + sanitized(link) + ".stl";
    io::write_mesh(*it->second, dir / mesh_file);
    written.push_back(dir / mesh_file);
    const std::string geometry = "<geometry><mesh filename=\"" + mesh_file + "\"/></geometry>";
    xml << ">\n    <visual>" << geometry << "</visual>\n    <collision>" << geometry << "</collision>\n  </link>\n";
  }
  const Eigen::Vector3d t = r.T_world_root.translation(), a = rpy(r.T_world_root.rotation());
  xml << "  <joint name=\"world_to_" << prefix.substr(0, prefix.size() - 1) << "\" type=\"fixed\">\n    <parent link=\"world\"/>\n    <child link=\""
      << prefix << m.root_link() << "\"/>\n    <origin xyz=\"" << xyz(t) << "\" rpy=\"" << xyz(a) << "\"/>\n  </joint>\n";
  for (const auto& j : m.joints()) {
    using T = RobotModel::Joint::Type;
    const char* type = j.type == T::revolute ? "revolute" : j.type == T::continuous ? "continuous" : j.type == T::prismatic ? "prismatic" : "fixed";
    xml << "  <joint name=\"" << prefix << j.name << "\" type=\"" << type << "\">\n    <parent link=\"" << prefix << j.parent
        << "\"/>\n    <child link=\"" << prefix << j.child << "\"/>\n    <origin xyz=\"" << xyz(j.T_parent_joint.translation()) << "\" rpy=\""
        << xyz(rpy(j.T_parent_joint.rotation())) << "\"/>\n";
    if (j.movable()) xml << "    <axis xyz=\"" << xyz(j.axis) << "\"/>\n";
    if (j.type == T::revolute || j.type == T::prismatic)
      xml << "    <limit lower=\"" << num(j.lower) << "\" upper=\"" << num(j.upper) << "\" effort=\"" << num(j.effort) << "\" velocity=\""
          << num(j.velocity) << "\"/>\n";
    xml << "  </joint>\n";
  }
  return xml.str();
}

// SDF: one model at T_world_root, its links at the description's zero configuration (where every
// joint is 0, as URDF-to-SDF converters place them), joints about axes in the child link's frame,
// fixed to the world. The current joint values are in a comment.
std::string robot_sdf(const SceneRobot& r, const std::string& name, const fs::path& dir, std::vector<fs::path>& written) {
  std::ostringstream xml;
  const auto& m = *r.model;
  std::map<std::string, Transform> T_root_link = {{m.root_link(), Transform::Identity()}};
  for (const auto& j : m.joints()) T_root_link[j.child] = T_root_link.at(j.parent) * j.T_parent_joint;
  xml << "    <!-- robot " << r.path << " (version " << r.version << "), current joint values:";
  for (const auto& n : m.joint_names()) xml << " " << n << "=" << num(r.joints.at(n));
  xml << " -->\n";
  const Eigen::Vector3d t = r.T_world_root.translation(), a = rpy(r.T_world_root.rotation());
  xml << "    <model name=\"" << name << "\">\n      <pose>" << xyz(t) << " " << xyz(a) << "</pose>\n";
  for (const auto& [link, T] : T_root_link) {
    xml << "      <link name=\"" << link << "\">\n        <pose>" << xyz(T.translation()) << " " << xyz(rpy(T.rotation())) << "</pose>\n";
    if (const auto it = m.link_meshes().find(link); it != m.link_meshes().end()) {
      const std::string mesh_file = "meshes/" + name + "_" + sanitized(link) + ".stl";
      io::write_mesh(*it->second, dir / mesh_file);
      written.push_back(dir / mesh_file);
      const std::string geometry = "<geometry><mesh><uri>" + mesh_file + "</uri></mesh></geometry>";
      xml << "        <visual name=\"visual\">" << geometry << "</visual>\n        <collision name=\"collision\">" << geometry << "</collision>\n";
    }
    xml << "      </link>\n";
  }
  xml << "      <joint name=\"world_to_" << name << "\" type=\"fixed\"><parent>world</parent><child>" << m.root_link() << "</child></joint>\n";
  for (const auto& j : m.joints()) {
    using T = RobotModel::Joint::Type;
    const char* type = j.type == T::prismatic ? "prismatic" : j.type == T::fixed ? "fixed" : "revolute";
    xml << "      <joint name=\"" << j.name << "\" type=\"" << type << "\"><parent>" << j.parent << "</parent><child>" << j.child << "</child>";
    if (j.movable()) {
      const double lo = std::isfinite(j.lower) ? j.lower : -1e16, hi = std::isfinite(j.upper) ? j.upper : 1e16;
      xml << "<axis><xyz>" << xyz(j.axis) << "</xyz><limit><lower>" << num(lo) << "</lower><upper>" << num(hi) << "</upper></limit></axis>";
    }
    xml << "</joint>\n";
  }
  xml << "    </model>\n";
  return xml.str();
}

void write_text(const fs::path& path, const std::string& text) {
  io::write_file_atomically(path, std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

}  // namespace

SceneFormat scene_format_from_string(const std::string& name) {
  if (name == "urdf") return SceneFormat::urdf;
  if (name == "sdf") return SceneFormat::sdf;
  if (name == "gltf") return SceneFormat::gltf;
  throw Error("unknown scene format '" + name + "' (use urdf, sdf or gltf)");
}

std::vector<fs::path> export_scene(const WorldModel& world, SceneFormat format, const fs::path& dir) {
  if (world.objects().empty()) throw Error("the world model of " + world.folder() + " is empty: nothing to export");
  std::vector<fs::path> written;
  std::error_code ec;
  const bool existed = fs::exists(dir, ec);
  try {
    fs::create_directories(dir);
    std::set<std::string> used;
    std::vector<std::string> names;
    for (const auto& o : world.objects()) names.push_back(link_name(o, used));
    const std::string scene_name = "artisan_scene" + (world.folder() == "/" ? std::string() : world.folder());
    if (format == SceneFormat::gltf) {
      std::vector<io::SceneNode> nodes;
      for (size_t k = 0; k < names.size(); ++k) nodes.push_back({names[k], world.objects()[k].mesh.get(), world.objects()[k].T_world_object});
      // Each robot link at the current joints.
      for (const auto& r : world.robots())
        for (const auto& [link, mesh] : r.model->link_meshes())
          nodes.push_back({sanitized(r.name) + "_" + sanitized(link), mesh.get(), r.T_world_links.at(link)});
      const fs::path file = dir / "scene.gltf";
      io::write_gltf_scene(nodes, file);
      written = {file, dir / "scene.bin"};
      return written;
    }
    fs::create_directories(dir / "meshes");
    std::ostringstream xml;
    std::string safe_name = scene_name;
    for (char& c : safe_name)
      if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
    if (format == SceneFormat::urdf) {
      xml << "<?xml version=\"1.0\"?>\n<!-- The world model of " << world.folder() << " (revision " << world.revision()
          << "), written by artisan export-scene. -->\n<robot name=\"" << safe_name << "\">\n  <link name=\"world\"/>\n";
    } else {
      xml << "<?xml version=\"1.0\"?>\n<!-- The world model of " << world.folder() << " (revision " << world.revision()
          << "), written by artisan export-scene. -->\n<sdf version=\"1.6\">\n  <world name=\"" << safe_name << "\">\n";
    }
    for (size_t k = 0; k < names.size(); ++k) {
      const auto& o = world.objects()[k];
      const std::string mesh_file = "meshes/" + names[k] + ".stl";
      io::write_mesh(*o.mesh, dir / mesh_file);
      written.push_back(dir / mesh_file);
      const Eigen::Vector3d t = o.T_world_object.translation(), r = rpy(o.T_world_object.rotation());
      const std::string geometry_urdf = "<geometry><mesh filename=\"" + mesh_file + "\"/></geometry>";
      if (format == SceneFormat::urdf) {
        xml << "  <link name=\"" << names[k] << "\">\n"
            << "    <visual>" << geometry_urdf << "</visual>\n"
            << "    <collision>" << geometry_urdf << "</collision>\n"
            << "  </link>\n"
            << "  <joint name=\"world_to_" << names[k] << "\" type=\"fixed\">\n"
            << "    <parent link=\"world\"/>\n    <child link=\"" << names[k] << "\"/>\n"
            << "    <origin xyz=\"" << num(t.x()) << " " << num(t.y()) << " " << num(t.z()) << "\" rpy=\"" << num(r.x()) << " "
            << num(r.y()) << " " << num(r.z()) << "\"/>\n"
            << "  </joint>\n";
      } else {
        const std::string geometry_sdf = "<geometry><mesh><uri>" + mesh_file + "</uri></mesh></geometry>";
        xml << "    <model name=\"" << names[k] << "\">\n      <static>true</static>\n"
            << "      <pose>" << num(t.x()) << " " << num(t.y()) << " " << num(t.z()) << " " << num(r.x()) << " " << num(r.y()) << " "
            << num(r.z()) << "</pose>\n"
            << "      <link name=\"link\">\n"
            << "        <visual name=\"visual\">" << geometry_sdf << "</visual>\n"
            << "        <collision name=\"collision\">" << geometry_sdf << "</collision>\n"
            << "      </link>\n    </model>\n";
      }
    }
    for (const auto& r : world.robots()) {
      std::string name = sanitized(r.name);
      for (int k = 2; used.count(name); ++k) name = sanitized(r.name) + "_" + std::to_string(k);
      used.insert(name);
      xml << (format == SceneFormat::urdf ? robot_urdf(r, name + "_", dir, written) : robot_sdf(r, name, dir, written));
    }
    const fs::path file = dir / (format == SceneFormat::urdf ? "scene.urdf" : "scene.sdf");
    xml << (format == SceneFormat::urdf ? "</robot>\n" : "  </world>\n</sdf>\n");
    write_text(file, xml.str());
    written.push_back(file);
    return written;
  } catch (...) {
    for (const auto& f : written) fs::remove(f, ec);
    if (!existed) fs::remove_all(dir, ec);
    throw;
  }
}

}  // namespace artisan::worldmodel
