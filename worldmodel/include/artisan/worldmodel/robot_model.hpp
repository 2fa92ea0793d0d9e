#pragma once
// A robot of the world model from URDF: forward kinematics over its joints and its collision
// geometry as one convex hull per link, so "is the arm at these joint values in collision?" is a
// CollisionScene query.
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "artisan/worldmodel/collision_scene.hpp"

namespace artisan::worldmodel {

class RobotModel {
 public:
  /// Reads `urdf`; "package://" URIs are looked up in `package_paths`. Links' collision meshes
  /// (any format assimp reads) and boxes, cylinders and spheres become convex hulls. Throws
  /// artisan::Error naming the file and what is wrong.
  static RobotModel load(const std::filesystem::path& urdf, const std::vector<std::filesystem::path>& package_paths = {});

  const std::string& name() const { return name_; }
  /// Movable joints (revolute, continuous, prismatic), root to tip.
  std::vector<std::string> joint_names() const;
  /// Pose of every link in the world for `joints` (missing joints are 0) with the root at
  /// T_world_root. Throws for an unknown joint, a non-finite value or one beyond its limits.
  std::map<std::string, Transform> link_poses(const std::map<std::string, double>& joints, const Transform& T_world_root) const;
  /// One convex query shape per link with collision geometry, named "ROBOT/LINK".
  std::vector<QueryShape> collision_shapes(const std::map<std::string, double>& joints, const Transform& T_world_root) const;

 private:
  struct Joint {
    std::string name, parent, child;
    enum class Type { fixed, revolute, continuous, prismatic } type = Type::fixed;
    Transform T_parent_joint = Transform::Identity();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
    double lower = 0, upper = 0;
  };
  std::string name_, root_;
  std::vector<Joint> joints_;  ///< parents before children
  std::map<std::string, std::vector<Eigen::Vector3f>> hulls_;  ///< link → points in the link frame
};

}  // namespace artisan::worldmodel
