#pragma once
// The LCM face of the world model: publishes the scene (snapshot on start, after each change
// and at a low rate; diffs at once, the environment's re-cut after an edit as a diff of its own
// when the worker has made it; the robots with their joint values), serves meshes in chunks,
// answers collision, distance and ray queries (collision and distance also for a robot at any
// joint values) and operator commands, re-reads the workspace for changes made by others, and
// sends a heartbeat. Malformed messages are counted and answered with an error; they never stop
// the service.
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include <lcm/lcm-cpp.hpp>

#include "artisan/worldmodel/world_model.hpp"

namespace artisan::teleop {

struct ServiceOptions {
  std::string folder = "/";             ///< the workcell folder served
  double snapshot_period_s = 2.0;       ///< full snapshot at least this often
  double heartbeat_period_s = 1.0;
  double poll_period_s = 0.5;           ///< re-read the workspace for others' changes
  std::string service_id;               ///< defaults to "artisand-<pid>"
  /// The environment is re-cut on a worker thread after an edit: the edited object's diff goes
  /// out at once, the environment's as a second diff when its cut is ready.
  worldmodel::WorldModelOptions world{.environment_in_background = true};
};

struct ServiceStats {
  int64_t queries_answered = 0;
  int64_t commands_applied = 0;
  int64_t commands_refused = 0;
  int64_t malformed_messages = 0;
  int64_t mesh_chunks_sent = 0;
  int64_t workspace_rereads = 0;  ///< polls that found a commit the world model had not read
};

class Service {
 public:
  /// Loads the world model of `options.folder` and subscribes on `lcm`. Throws artisan::Error
  /// when the folder is missing or the LCM instance is not good.
  Service(worldmodel::Workspace& workspace, lcm::LCM& lcm, ServiceOptions options = {});
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  /// Periodic work: publishes the snapshot/heartbeat when due and looks for workspace changes.
  /// Call it between lcm.handleTimeout() calls; it does not block.
  void tick();
  /// Handles messages and ticks until `stop` becomes true.
  void run(const std::atomic<bool>& stop);

  const worldmodel::WorldModel& world() const;
  const ServiceStats& stats() const;
  void publish_snapshot();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artisan::teleop
