#include "artisan/worldmodel/scene_export.hpp"

#include <cstdio>
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
