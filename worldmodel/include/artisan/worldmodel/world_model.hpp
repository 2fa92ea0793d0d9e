#pragma once
// The world model of one workcell folder: the environment (merged meshes, else the members of
// the newest MultiMesh at their registered poses, else the folder's meshes), with the surface of
// recognized objects (and of the robots at their current joints) cut out, plus every recognized
// object with its pose, model, score and grasp frames, the robots (robot_store.hpp) with their
// joint values; and its collision scene, which answers queries for a robot at any joints.
//
// The world frame: a MultiMesh is placed by its root member's sensor pose when the image that
// mesh was made from knows it (simulated and tracked sensors: image metadata
// sensor.T_world_sensor), else at the identity; a merged mesh sits where its MultiMesh does; a
// lone mesh at its own sensor pose when known. Recognized objects follow the mesh they were
// found in, until an operator edits them: an edit's version holds the world pose. Operator edits
// (correct or accept a pose, attach, detach, delete, add) are stored in the workspace as new
// versions with author and time, and refresh() rebuilds only what changed.
//
// The environment's cut (and its encoding, hash and hierarchy) depends on every object's pose,
// and takes seconds for a million triangles. With `environment_in_background`, an edit updates
// its object at once (reading back only that object's new row) and leaves the re-cut to a worker
// thread; poll_environment() installs it as a change of its own, and frees the environment it
// replaces on another thread. Until then the environment stays as cut before the edit.
#include <cstdint>
#include <future>
#include <map>
#include <unordered_map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "artisan/worldmodel/collision_scene.hpp"
#include "artisan/worldmodel/robot_model.hpp"
#include "artisan/worldmodel/workspace.hpp"

namespace artisan::worldmodel {

struct SceneObject {
  ObjectId object_id = 0;   ///< stable: the ID of the object's first version
  ObjectId version_id = 0;  ///< the workspace row of the current version
  int version = 1;
  std::string path;
  enum class Kind { environment, object } kind = Kind::object;
  std::string model;        ///< model name (objects)
  ObjectId model_id = 0;
  Transform T_world_object = Transform::Identity();
  double score = 0.0;
  double overlap = 0.0;
  bool ambiguous = false;   ///< another pose or another model fits as well:
  std::string alternative_model;                        ///< its model ("" when not ambiguous)
  Transform T_world_alternative = Transform::Identity();  ///< and its pose
  std::string status;       ///< "recognized", "accepted", "corrected", "added" (environment: "environment")
  std::vector<Transform> T_world_grasps;
  std::string attached_to;  ///< "" or e.g. "ur5/tool0"
  Transform T_link_object = Transform::Identity();
  double margin_m = 0.0;
  std::shared_ptr<const TriangleMesh> mesh;  ///< in the object frame (the environment: cut)
  std::string mesh_hash;    ///< 16 hex digits over the encoded mesh

  bool same_state(const SceneObject& o) const;  ///< same version, pose, status and mesh
};

/// A robot of the world model at its current joint values (as stored in the workspace).
struct SceneRobot {
  ObjectId object_id = 0;   ///< stable: the ID of the robot object's first version
  ObjectId version_id = 0;  ///< the workspace row of the current version
  int version = 1;
  std::string name;         ///< the robot object's name: its links' shapes are "NAME/LINK"
  std::string path;
  std::shared_ptr<const RobotModel> model;
  Transform T_world_root = Transform::Identity();
  std::map<std::string, double> joints;            ///< every movable joint [rad or m]
  std::map<std::string, Transform> T_world_links;  ///< every link at `joints`
};

/// A robot at a joint configuration, for collision and distance queries.
struct RobotQuery {
  std::string robot;                     ///< its name; "" for the folder's only robot
  std::map<std::string, double> joints;  ///< [rad or m]; joints not named keep their current values
};

struct WorldModelOptions {
  double cutout_distance_m = 0.004;  ///< environment triangles this near a recognized object are its surface
  double object_margin_m = 0.0;      ///< collision margin of recognized objects [m]
  double environment_margin_m = 0.0; ///< collision margin of the environment [m]
  /// Re-cut the environment on a worker thread when only objects moved (see poll_environment());
  /// otherwise refresh() and every edit re-cut it before returning.
  bool environment_in_background = false;
  /// Cut the robots' own surface (their links at the current joints) out of the environment like
  /// a recognized object's: the sensors scanned the arm too.
  bool cut_out_robots = true;
};

struct SceneChanges {
  std::vector<ObjectId> changed;  ///< new or changed objects (object_id)
  std::vector<ObjectId> removed;
  bool robots = false;  ///< a robot was added, removed or changed (pose, joints, description)
  bool empty() const { return changed.empty() && removed.empty() && !robots; }
};

class WorldModel {
 public:
  /// The world model of `folder` ("/" for the whole workspace). Throws when it is not a folder.
  WorldModel(Workspace& workspace, std::string folder, WorldModelOptions options = {});
  ~WorldModel();
  WorldModel(const WorldModel&) = delete;
  WorldModel& operator=(const WorldModel&) = delete;

  const std::string& folder() const { return folder_; }
  /// Bumps on every change (edits, others' changes, background re-cuts): the workspace's newest
  /// row x 1000 plus the changes since, so it grows across restarts.
  int64_t revision() const { return revision_; }
  const std::vector<SceneObject>& objects() const { return objects_; }
  const SceneObject* find(ObjectId object_id) const;
  /// A mesh of the scene by hash, encoded (artisan mesh format); throws for an unknown hash.
  const std::vector<uint8_t>& encoded_mesh(const std::string& hash) const;
  const CollisionScene& collision() const { return *collision_; }

  // --- robots ----------------------------------------------------------------------------------
  const std::vector<SceneRobot>& robots() const { return robots_; }
  /// The robot named `name` ("" for the only one). Throws naming the robots there are.
  const SceneRobot& robot(const std::string& name = "") const;
  /// Joint values as a client sends them: with `names`, one value per name; without, one value
  /// per joint of the robot in its order (SceneRobot::model->joint_names()); neither: none (the
  /// current joints). Throws naming the counts and the joints when they do not match, and for an
  /// unknown name, a value that is not finite or beyond its limits.
  std::map<std::string, double> joint_values(const std::string& robot, const std::vector<std::string>& names,
                                             const std::vector<double>& values) const;
  /// The robot at the query's joints as query shapes: one convex hull per link ("NAME/LINK"), and
  /// every object attached to one of its links (attach()) as the convex hull of its mesh at
  /// T_world_link * T_link_object, named by the object's path. Shapes are checked against the
  /// scene's bodies, never against each other: the robot's links do not collide with each other.
  /// Throws for an unknown robot or joint, a value that is not finite or beyond its limits.
  std::vector<QueryShape> robot_shapes(const RobotQuery& query) const;
  /// The robot at the query's joints (with `extra` shapes, e.g. a tool) against the scene.
  CollisionResult check_robot(const RobotQuery& query, const std::vector<AllowedPair>& allowed = {}, const CheckOptions& options = {},
                              const std::vector<QueryShape>& extra = {}) const;
  DistanceResult robot_distance(const RobotQuery& query, double max_distance_m, const std::vector<AllowedPair>& allowed = {},
                                const std::vector<QueryShape>& extra = {}) const;

  /// Re-reads the folder; updates the scene and the collision scene where they changed.
  SceneChanges refresh();
  /// Whether anything was committed to the workspace that this model has not read: by another
  /// connection, or through the workspace other than by this model's own edits (which it
  /// applies as it makes them). When false, refresh() would find nothing.
  bool workspace_changed() const { return ws_.change_stamp() != read_; }
  /// What the last refresh (or edit, or installed environment) changed.
  const SceneChanges& last_changes() const { return last_changes_; }
  /// True while an environment re-cut is under way on the worker thread.
  bool environment_pending() const { return job_.valid(); }
  /// Installs a finished background re-cut of the environment (waits for it when `wait`):
  /// the environment's mesh, hash and collision body change and the revision bumps. Returns
  /// what changed (nothing when no re-cut had finished). Starts the next re-cut when objects
  /// moved again meanwhile.
  SceneChanges poll_environment(bool wait = false);

  // --- operator edits: each stored as a new version (author, time, action), then refreshed ---
  ObjectId correct_pose(ObjectId object_id, const Transform& T_world_object, const std::string& author);
  ObjectId accept_pose(ObjectId object_id, const std::string& author);
  ObjectId attach(ObjectId object_id, const std::string& link, const Transform& T_link_object, const std::string& author);
  ObjectId detach(ObjectId object_id, const std::string& author);
  ObjectId remove_object(ObjectId object_id, const std::string& author);
  /// A new object of `model` (path, ID or name of a model object) at `T_world_object`.
  ObjectId add_object(const std::string& model, const Transform& T_world_object, const std::string& author);
  /// Runs recognition again on the environment meshes (every model); returns the objects made.
  std::vector<ObjectId> rerecognize();

 private:
  struct Loaded;
  struct EnvironmentCut;
  Loaded load();
  /// The scene object of a recognized model's row (T_world_mesh: where the meshes it may have been
  /// found in sit, for rows that hold their pose relative to that mesh).
  SceneObject scene_object(const ObjectInfo& row, const std::map<ObjectId, Transform>& T_world_mesh, const std::vector<SceneRobot>& robots);
  /// The inputs of the environment's cut for these objects and robots.
  std::shared_ptr<EnvironmentCut> make_cut(const std::string& whole_signature, const std::vector<SceneObject>& objects,
                                           const std::vector<SceneRobot>& robots) const;
  /// After this model's own edit made row `version_id` (a new version of `object_id`, or 0 for a
  /// new object): updates that object alone.
  void apply_edit(ObjectId object_id, ObjectId version_id);
  /// The hash of a mesh of the scene: an object's already using it, else encoded (and kept) now.
  std::string mesh_hash(const std::shared_ptr<const TriangleMesh>& mesh);
  void start_environment_job();
  ObjectId edit(ObjectId object_id, const std::string& action, const std::string& author, nlohmann::json changes);
  const SceneObject& object_or_throw(ObjectId object_id) const;

  Workspace& ws_;
  std::string folder_;
  WorldModelOptions options_;
  int64_t revision_ = 0;
  SceneChanges last_changes_;
  ChangeStamp read_;  ///< the workspace as last read (taken before the read) or edited by this model
  std::vector<SceneObject> objects_;
  std::vector<SceneRobot> robots_;
  std::map<ObjectId, SceneRobot> robot_versions_;  ///< loaded robot versions, by workspace row
  /// Each row's first version (rows never change, and IDs are never reused).
  std::unordered_map<ObjectId, ObjectId> first_versions_;
  ObjectId first_version(const ObjectInfo& info);
  /// Hull vertices of attached objects' meshes, by mesh.
  std::map<const TriangleMesh*, std::pair<std::shared_ptr<const TriangleMesh>, std::vector<Eigen::Vector3f>>> attached_hulls_;
  std::unique_ptr<CollisionScene> collision_;
  mutable std::map<ObjectId, std::shared_ptr<const TriangleMesh>> model_meshes_;  ///< by model row
  std::map<ObjectId, ObjectInfo> model_infos_;                                    ///< by model row (rows never change)
  std::map<std::string, std::vector<uint8_t>> encoded_;                          ///< by hash
  std::string environment_signature_;  ///< the meshes and cut-out objects it was made from
  std::shared_ptr<const TriangleMesh> environment_mesh_;
  std::string whole_signature_;        ///< the meshes (and their poses) the uncut environment was made from
  std::shared_ptr<const TriangleMesh> whole_environment_;  ///< uncut, in the world frame
  std::shared_ptr<const EnvironmentCut> latest_;  ///< the cut the objects ask for now (its inputs)
  std::future<std::unique_ptr<EnvironmentCut>> job_;
  /// Frees what a new environment replaced on another thread (see poll_environment()).
  void release(std::vector<std::shared_ptr<const void>> garbage);
  std::future<void> release_;
};

/// 16 hex digits of FNV-1a 64 over `bytes`.
std::string content_hash(const std::vector<uint8_t>& bytes);

}  // namespace artisan::worldmodel
