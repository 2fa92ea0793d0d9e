// `artisan robot ...`: a robot (URDF, pose, joint values) in a workcell folder's world model.
// The URDF and the collision meshes it names are copied into the workspace; every change is a
// new version of the robot object with author and time (worldmodel/robot_store.hpp).
#include <cmath>
#include <cstdlib>
#include <iomanip>
#include <iostream>

#include "artisan/core/error.hpp"
#include "artisan/worldmodel/robot_store.hpp"
#include "commands.hpp"

namespace artisan::cli {
namespace {

using json = nlohmann::json;

struct RobotOptions {
  std::string folder, name, urdf, pose, author;
  std::vector<std::string> package_paths, joints;
};

json robot_json(const worldmodel::StoredRobot& r) {
  json joints = json::object();
  for (const auto& name : r.model->joint_names()) joints[name] = r.joints.at(name);
  json links = json::object();
  for (const auto& [link, T] : r.model->link_poses(r.joints, r.T_world_root)) links[link] = to_row_major(T);
  return {{"id", r.info.id},
          {"path", r.info.path},
          {"name", r.info.name},
          {"urdf_robot", r.info.subkind},
          {"version", r.info.version},
          {"T_world_root", to_row_major(r.T_world_root)},
          {"joint_names", r.model->joint_names()},
          {"joints", joints},
          {"T_world_links", links},
          {"edit", r.info.metadata.value("edit", json(nullptr))}};
}

void print_robot(const worldmodel::StoredRobot& r) {
  const Eigen::Vector3d t = r.T_world_root.translation();
  std::cout << r.info.path << " (robot '" << r.info.subkind << "', version " << r.info.version << ") at (" << std::fixed << std::setprecision(3)
            << t.x() << ", " << t.y() << ", " << t.z() << ") m\n";
  for (const auto& name : r.model->joint_names()) std::cout << "  " << std::left << std::setw(24) << name << std::right << std::setprecision(4) << r.joints.at(name) << "\n";
  if (r.info.metadata.contains("edit"))
    std::cout << "  last change: " << r.info.metadata["edit"].value("action", "") << " by " << r.info.metadata["edit"].value("author", "") << " at "
              << r.info.metadata["edit"].value("at", "") << "\n";
}

}  // namespace

std::map<std::string, double> parse_joint_values(const std::vector<std::string>& assignments, const std::string& option) {
  std::map<std::string, double> joints;
  for (const auto& a : assignments) {
    const auto eq = a.find('=');
    const std::string name = eq == std::string::npos ? "" : a.substr(0, eq), value = eq == std::string::npos ? "" : a.substr(eq + 1);
    char* end = nullptr;
    const double v = value.empty() ? NAN : std::strtod(value.c_str(), &end);
    if (name.empty() || value.empty() || !end || *end != '\0')
      throw Error(option + " '" + a + "': expected NAME=VALUE, VALUE a number [rad or m]");
    if (!std::isfinite(v)) throw Error(option + " '" + a + "': the value of joint '" + name + "' is not finite");
    if (!joints.emplace(name, v).second) throw Error(option + ": joint '" + name + "' is given twice");
  }
  return joints;
}

void add_robot_commands(CLI::App& app, const GlobalOptions& options, Action& action) {
  auto o = std::make_shared<RobotOptions>();
  auto* robot = app.add_subcommand("robot", "A robot (URDF, pose, joint values) in a workcell folder's world model");
  robot->require_subcommand(1);

  auto* set = robot->add_subcommand("set", "Add a robot to a folder, or change its pose, joint values or description (a new version)");
  set->add_option("folder", o->folder, "Workcell folder")->required();
  set->add_option("--urdf", o->urdf, "URDF file (required for a new robot); it and its collision meshes are copied into the workspace");
  set->add_option("--package-path", o->package_paths, "Where package:// URIs are looked up (repeatable)");
  set->add_option("--pose", o->pose, "T_world_root: \"tx ty tz qx qy qz qw\" or 16 numbers (required for a new robot)");
  set->add_option("--joint", o->joints, "NAME=VALUE [rad or m] (repeatable); joints not given keep their values");
  set->add_option("--name", o->name, "The robot object's name (default: the URDF's robot name, or the folder's only robot)");
  set->add_option("--author", o->author, "Who makes the change (default: $USER)");
  set->callback([&options, &action, o] {
    action = [&options, o] {
      worldmodel::RobotSetRequest req;
      req.folder = o->folder;
      req.name = o->name;
      if (!o->urdf.empty()) req.urdf = o->urdf;
      for (const auto& p : o->package_paths) req.package_paths.push_back(p);
      if (!o->pose.empty()) req.T_world_root = parse_transform(o->pose);
      req.joints = parse_joint_values(o->joints, "--joint");
      const char* user = std::getenv("USER");
      req.author = !o->author.empty() ? o->author : user ? user : "operator";
      auto ws = worldmodel::Workspace::open(options.db);
      const auto id = worldmodel::set_robot(ws, req);
      const auto stored = worldmodel::load_robot(ws, id);
      if (options.json) std::cout << robot_json(stored).dump(2) << "\n";
      else if (!options.quiet) {
        std::cerr << (stored.info.version == 1 ? "added " : "stored version " + std::to_string(stored.info.version) + " of ") << stored.info.path
                  << " (ID " << id << ")\n";
      }
      return 0;
    };
  });

  auto* show = robot->add_subcommand("show", "The robots of a folder with their pose and joint values");
  show->add_option("folder", o->folder, "Workcell folder")->required();
  show->add_option("--name", o->name, "Only this robot");
  show->callback([&options, &action, o] {
    action = [&options, o] {
      auto ws = worldmodel::Workspace::open(options.db);
      json out = json::array();
      size_t shown = 0;
      for (const auto& info : worldmodel::find_robots(ws, o->folder)) {
        if (!o->name.empty() && info.name != o->name) continue;
        const auto r = worldmodel::load_robot(ws, info.id);
        ++shown;
        if (options.json) out.push_back(robot_json(r));
        else print_robot(r);
      }
      if (!o->name.empty() && shown == 0) throw Error(o->folder + " has no robot '" + o->name + "'");
      if (options.json) std::cout << out.dump(2) << "\n";
      else if (shown == 0 && !options.quiet) std::cerr << o->folder << " has no robot (add one with `artisan robot set`)\n";
      return 0;
    };
  });
}

}  // namespace artisan::cli
