#pragma once
// A robot of the world model from URDF: forward kinematics over its joints and its collision
// geometry as one convex hull per link, so "is the arm at these joint values in collision?" is a
// CollisionScene query.
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "artisan/core/triangle_mesh.hpp"
#include "artisan/worldmodel/collision_scene.hpp"

namespace artisan::worldmodel {

class RobotModel {
 public:
  /// The mesh a URDF names (the URI as written: "package://...", a relative or an absolute path).
  using MeshSource = std::function<TriangleMesh(const std::string& uri)>;

  struct Joint {
    std::string name, parent, child;
    enum class Type { fixed, revolute, continuous, prismatic } type = Type::fixed;
    Transform T_parent_joint = Transform::Identity();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  ///< unit, in the joint (child link) frame
    double lower = 0, upper = 0;                      ///< revolute [rad], prismatic [m]; continuous: ±infinity
    double effort = 0, velocity = 0;                  ///< as the URDF gives them [N m or N, rad/s or m/s]
    bool movable() const { return type != Type::fixed; }
  };

  /// Reads `urdf`; "package://" URIs are looked up in `package_paths`. Links' collision meshes
  /// (any format assimp reads) and boxes, cylinders and spheres become convex hulls. Throws
  /// artisan::Error naming the file and what is wrong.
  static RobotModel load(const std::filesystem::path& urdf, const std::vector<std::filesystem::path>& package_paths = {});
  /// The same from URDF text: `source` names it in errors, `meshes` gives the collision meshes
  /// it references (e.g. copies kept in a workspace).
  static RobotModel parse(const std::string& urdf_text, const std::string& source, const MeshSource& meshes);
  /// The URIs of the collision meshes `urdf_text` references, each once, in link order.
  static std::vector<std::string> collision_mesh_uris(const std::string& urdf_text, const std::string& source);
  /// Finds a URI of `urdf` on disk the way load() does; throws naming the URI when it is not found.
  static std::filesystem::path resolve_uri(const std::string& uri, const std::filesystem::path& urdf,
                                           const std::vector<std::filesystem::path>& package_paths);

  /// Prefixes the shape names ("NAME/LINK"); the URDF's robot name by default.
  const std::string& name() const { return name_; }
  void set_name(std::string name) { name_ = std::move(name); }
  const std::string& root_link() const { return root_; }
  /// Movable joints (revolute, continuous, prismatic), root to tip.
  std::vector<std::string> joint_names() const;
  /// Every joint, parents before children.
  const std::vector<Joint>& joints() const { return joints_; }
  /// Each movable joint at 0, or at its nearer limit when 0 is outside its limits.
  std::map<std::string, double> default_joints() const;
  /// Throws artisan::Error naming the joint and the value for an unknown joint (the message lists
  /// the robot's joints), a non-finite value or one beyond its limits.
  void check_joints(const std::map<std::string, double>& joints) const;
  /// Pose of every link in the world for `joints` (missing joints at their default) with the
  /// root at T_world_root. Throws as check_joints().
  std::map<std::string, Transform> link_poses(const std::map<std::string, double>& joints, const Transform& T_world_root) const;
  /// One convex query shape per link with collision geometry, named "ROBOT/LINK".
  std::vector<QueryShape> collision_shapes(const std::map<std::string, double>& joints, const Transform& T_world_root) const;
  /// The collision geometry of each link that has one, in the link frame: meshes scaled and
  /// placed as the URDF says, boxes, cylinders and spheres triangulated.
  const std::map<std::string, std::shared_ptr<const TriangleMesh>>& link_meshes() const { return meshes_; }

 private:
  std::string name_, root_;
  std::vector<Joint> joints_;  ///< parents before children
  std::map<std::string, std::shared_ptr<const TriangleMesh>> meshes_;  ///< link → collision geometry, link frame
  std::map<std::string, std::vector<Eigen::Vector3f>> hulls_;  ///< link → convex hull vertices, link frame
};

/// The vertices of the convex hull of `points` (a subset of them); fewer than 4 when they are flat.
std::vector<Eigen::Vector3f> convex_hull_vertices(const std::vector<Eigen::Vector3f>& points);

}  // namespace artisan::worldmodel
