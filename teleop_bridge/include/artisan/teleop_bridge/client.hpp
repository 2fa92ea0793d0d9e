#pragma once
// A client of the world-model service: rebuilds the scene from LCM alone (snapshot, diffs and
// meshes fetched by hash, robots with their joint values), asks queries (also for a robot at
// any joint values) and sends commands, each matched to its reply by
// request ID. What a teleoperation or planning tool links against.
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "artisan/command_result_t.hpp"
#include "artisan/command_t.hpp"
#include "artisan/query_reply_t.hpp"
#include "artisan/query_t.hpp"
#include "artisan/robot_state_t.hpp"
#include "artisan/scene_object_t.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::teleop {

struct RemoteObject {
  artisan::scene_object_t info;               ///< as the service published it
  Transform T_world_object = Transform::Identity();
  std::vector<Transform> T_world_grasps;
  Transform T_world_alternative = Transform::Identity();  ///< when info.ambiguous: the alternative's pose (its model: info.alternative_model)
  std::shared_ptr<const TriangleMesh> mesh;  ///< once fetched (object frame)
};

class SceneClient {
 public:
  /// `pump` handles pending LCM messages for up to the given milliseconds; by default
  /// lcm.handleTimeout(). In-process tests pass one that also ticks the service.
  SceneClient(lcm::LCM& lcm, std::string client_id, std::function<void(int)> pump = {});
  ~SceneClient();
  SceneClient(const SceneClient&) = delete;
  SceneClient& operator=(const SceneClient&) = delete;

  /// Waits for a snapshot and, when `with_meshes`, fetches every mesh it references. Returns
  /// false on timeout.
  bool wait_for_scene(double timeout_s, bool with_meshes = true);
  /// Waits until the scene has reached at least `revision`.
  bool wait_for_revision(int64_t revision, double timeout_s);

  bool has_scene() const;
  int64_t revision() const;
  std::string folder() const;
  std::string service_id() const;
  const std::map<int64_t, RemoteObject>& objects() const;
  /// The robots at their current joint values, as the service last published them.
  const std::vector<artisan::robot_state_t>& robots() const;
  /// Meshes fetched so far, by hash (each checked against its hash).
  size_t meshes_fetched() const;
  /// Diffs and snapshots received.
  int64_t updates_received() const;

  /// Puts `robot` (its name, or "" for the scene's only robot) at `joints` into `query`: its
  /// links (and what they carry) are then checked with the query's shapes. Joints not named keep
  /// their current values.
  static void set_robot(artisan::query_t& query, const std::string& robot, const std::map<std::string, double>& joints);
  /// Sends `query` (client_id and request_id filled in) and waits for its reply; throws
  /// artisan::Error on timeout.
  artisan::query_reply_t query(artisan::query_t query, double timeout_s = 5.0);
  /// Sends `command` (client_id and request_id filled in) and waits for its result.
  artisan::command_result_t command(artisan::command_t command, double timeout_s = 30.0);

  /// Handles messages for up to `ms` milliseconds.
  void pump(int ms);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artisan::teleop
