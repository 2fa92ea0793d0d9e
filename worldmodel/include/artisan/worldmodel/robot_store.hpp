#pragma once
// Robots in the workspace. A robot object (kind "robot", in a workcell folder) keeps the URDF
// text and a copy of every collision mesh it names (so the workspace needs no files from
// elsewhere), where the URDF's root link is in the world, and the value of every movable joint.
// Each change (pose, joint values, a new description) is a new version of the object with author
// and time, like the operator's edits of recognized objects.
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "artisan/worldmodel/robot_model.hpp"
#include "artisan/worldmodel/workspace.hpp"

namespace artisan::worldmodel {

struct RobotSetRequest {
  std::string folder = "/";  ///< the workcell folder
  /// The robot object's name. Default: the URDF's robot name when a URDF is given, else the
  /// folder's only robot.
  std::string name;
  std::optional<std::filesystem::path> urdf;          ///< a (new) description: required for a new robot
  std::vector<std::filesystem::path> package_paths;  ///< where "package://" URIs are looked up
  std::optional<Transform> T_world_root;              ///< where the root link is: required for a new robot
  /// Joint values to set [rad or m]; the others keep their values (a new robot: 0, or the nearer
  /// limit when 0 is outside the limits).
  std::map<std::string, double> joints;
  std::string author;
};

struct StoredRobot {
  ObjectInfo info;                           ///< this version of the robot object
  std::shared_ptr<const RobotModel> model;   ///< shapes named "OBJECT_NAME/LINK"
  Transform T_world_root = Transform::Identity();
  std::map<std::string, double> joints;      ///< every movable joint
};

/// Stores a new robot in `request.folder`, or a new version of the robot of that name. Throws
/// artisan::Error naming what is wrong (no URDF or pose for a new robot, an unreadable URDF, a
/// mesh it names that cannot be found, an unknown joint, a value that is not finite or beyond
/// its limits, no author); nothing is stored then.
ObjectId set_robot(Workspace& workspace, const RobotSetRequest& request);
/// Reads a robot object (any version) back. Throws when it is not a robot or its data is damaged.
StoredRobot load_robot(const Workspace& workspace, ObjectId id);
/// The robots (latest versions) in `folder` and its subfolders.
std::vector<ObjectInfo> find_robots(const Workspace& workspace, const std::string& folder);

}  // namespace artisan::worldmodel
