#include "artisan/teleop_bridge/service.hpp"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <set>

#include "artisan/command_result_t.hpp"
#include "artisan/command_t.hpp"
#include "artisan/core/error.hpp"
#include "artisan/environment_reading_t.hpp"
#include "artisan/heartbeat_t.hpp"
#include "artisan/mesh_chunk_t.hpp"
#include "artisan/mesh_request_t.hpp"
#include "artisan/query_reply_t.hpp"
#include "artisan/query_t.hpp"
#include "artisan/scene_diff_t.hpp"
#include "artisan/scene_snapshot_t.hpp"
#include "artisan/service_error_t.hpp"
#include "artisan/teleop_bridge/channels.hpp"
#include "convert.hpp"

namespace artisan::teleop {
namespace {

using Clock = std::chrono::steady_clock;
using worldmodel::ObjectId;

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Limits on what a client may ask in one message.
constexpr int kMaxShapes = 1024;
constexpr int kMaxRays = 100000;
constexpr int kMaxAllowed = 4096;
constexpr int kMaxJoints = 256;

template <typename Msg>
bool decode(const lcm::ReceiveBuffer* rbuf, Msg& msg) {
  return msg.decode(rbuf->data, 0, int(rbuf->data_size)) == int(rbuf->data_size);
}

}  // namespace

struct Service::Impl {
  worldmodel::Workspace& ws;
  lcm::LCM& lcm;
  ServiceOptions options;
  worldmodel::WorldModel world;
  ServiceStats stats;
  Clock::time_point started = Clock::now(), last_snapshot{}, last_heartbeat{}, last_poll = Clock::now();
  std::vector<lcm::Subscription*> subscriptions;
  std::string status = "ok";
  std::set<ObjectId> environment_published;

  Impl(worldmodel::Workspace& w, lcm::LCM& l, ServiceOptions o)
      : ws(w), lcm(l), options(std::move(o)), world(ws, options.folder, options.world) {
    if (!lcm.good()) throw Error("LCM is not available (bad URL or no network)");
    ws.maintain_in_background();  // an edit's commit never waits for a checkpoint's fsync
    if (options.service_id.empty()) options.service_id = "artisand-" + std::to_string(::getpid());
  }

  void error(const std::string& channel, const std::string& message) {
    ++stats.malformed_messages;
    artisan::service_error_t e;
    e.utime = now_utime();
    e.channel = channel;
    e.message = message;
    lcm.publish(kServiceErrorChannel, &e);
  }

  void publish_snapshot() {
    artisan::scene_snapshot_t s;
    s.utime = now_utime();
    s.service_id = options.service_id;
    s.revision = world.revision();
    s.folder = world.folder();
    for (const auto& o : world.objects()) {
      auto m = to_lcm(o);
      m.mesh.n_bytes = int64_t(world.encoded_mesh(o.mesh_hash).size());
      s.objects.push_back(std::move(m));
    }
    s.n_objects = int32_t(s.objects.size());
    for (const auto& r : world.robots()) s.robots.push_back(to_lcm(r));
    s.n_robots = int32_t(s.robots.size());
    lcm.publish(kSceneChannel, &s);
    last_snapshot = Clock::now();
  }

  void publish_changes(int64_t base_revision, const worldmodel::SceneChanges& changes) {
    if (changes.empty()) return;
    artisan::scene_diff_t d;
    d.utime = now_utime();
    d.service_id = options.service_id;
    d.base_revision = base_revision;
    d.revision = world.revision();
    for (ObjectId id : changes.changed) {
      const auto* o = world.find(id);
      if (!o) continue;
      auto m = to_lcm(*o);
      m.mesh.n_bytes = int64_t(world.encoded_mesh(o->mesh_hash).size());
      d.changed.push_back(std::move(m));
    }
    d.n_changed = int32_t(d.changed.size());
    d.removed = changes.removed;
    d.n_removed = int32_t(d.removed.size());
    d.robots_changed = changes.robots;
    if (changes.robots)
      for (const auto& r : world.robots()) d.robots.push_back(to_lcm(r));
    d.n_robots = int32_t(d.robots.size());
    lcm.publish(kSceneDiffChannel, &d);
  }

  void publish_environment() {
    // Environmental readings stored with the acquisitions of the folder, each once.
    std::vector<worldmodel::ObjectInfo> stack = ws.children(ws.folder(world.folder()).id);
    while (!stack.empty()) {
      const auto o = stack.back();
      stack.pop_back();
      if (o.kind == worldmodel::ObjectKind::kFolder) {
        for (auto& c : ws.children(o.id)) stack.push_back(std::move(c));
        continue;
      }
      if (o.kind != worldmodel::ObjectKind::kImage || !o.metadata.contains("environment") || environment_published.count(o.id)) continue;
      environment_published.insert(o.id);
      const auto& e = o.metadata["environment"];
      artisan::environment_reading_t r;
      r.utime = now_utime();
      r.image_path = o.path;
      // Where the rig was: the translation of T_world_rig (row-major 4x4: elements 3, 7, 11).
      const auto T = e.value("T_world_rig", std::vector<double>{});
      for (int k = 0; k < 3; ++k) r.position[k] = T.size() == 16 ? T[size_t(4 * k + 3)] : 0.0;
      r.dose_rate_uSv_per_h = e.value("dose_rate_uSv_per_h", 0.0);
      r.temperature_C = e.value("temperature_C", 0.0);
      r.humidity_percent = e.value("humidity_percent", 0.0);
      lcm.publish(kEnvironmentChannel, &r);
    }
  }

  // Re-reads the workspace when anything was committed that the world model has not read.
  void refresh() {
    if (!world.workspace_changed()) return;
    const int64_t base = world.revision();
    ++stats.workspace_rereads;
    try {
      publish_changes(base, world.refresh());
      publish_environment();
      status = "ok";
    } catch (const std::exception& e) {
      status = std::string("cannot read the workspace: ") + e.what();
    }
  }

  void on_mesh_request(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    artisan::mesh_request_t req;
    if (!decode(rbuf, req)) return error(channel, "cannot decode mesh_request_t (" + std::to_string(rbuf->data_size) + " bytes)");
    const std::vector<uint8_t>* bytes = nullptr;
    try {
      bytes = &world.encoded_mesh(req.hash);
    } catch (const Error& e) {
      return error(channel, e.what());
    }
    const int n = int((bytes->size() + kMeshChunkBytes - 1) / kMeshChunkBytes);
    std::vector<int32_t> wanted = req.chunks;
    if (wanted.empty())
      for (int i = 0; i < n; ++i) wanted.push_back(i);
    for (const int32_t i : wanted) {
      if (i < 0 || i >= n)
        return error(channel, "mesh " + req.hash + " has " + std::to_string(n) + " chunks, not a chunk " + std::to_string(i));
      artisan::mesh_chunk_t c;
      c.utime = now_utime();
      c.hash = req.hash;
      c.chunk_index = i;
      c.n_chunks = n;
      c.total_bytes = int64_t(bytes->size());
      const size_t begin = size_t(i) * kMeshChunkBytes, end = std::min(bytes->size(), begin + kMeshChunkBytes);
      c.data.assign(bytes->begin() + long(begin), bytes->begin() + long(end));
      c.n_bytes = int32_t(c.data.size());
      lcm.publish(kMeshChunkChannel, &c);
      ++stats.mesh_chunks_sent;
    }
  }

  void on_query(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    artisan::query_t q;
    if (!decode(rbuf, q)) return error(channel, "cannot decode query_t (" + std::to_string(rbuf->data_size) + " bytes)");
    const auto t0 = Clock::now();
    artisan::query_reply_t r;
    r.client_id = q.client_id;
    r.request_id = q.request_id;
    r.revision = world.revision();
    r.ok = true;
    r.in_collision = false;
    r.min_distance = 0;
    try {
      if (q.n_shapes > kMaxShapes || q.n_rays > kMaxRays || q.n_allowed > kMaxAllowed || q.n_joint_names > kMaxJoints ||
          q.n_joint_values > kMaxJoints)
        throw Error("too large: at most " + std::to_string(kMaxShapes) + " shapes, " + std::to_string(kMaxRays) + " rays, " +
                    std::to_string(kMaxAllowed) + " allowed pairs, " + std::to_string(kMaxJoints) + " joints");
      std::vector<worldmodel::QueryShape> shapes;
      for (const auto& s : q.shapes) {
        const std::vector<Eigen::Vector3f>* hull = nullptr;
        if (s.kind == artisan::shape_t::CONVEX_MESH)
          for (const auto& o : world.objects())
            if (o.mesh_hash == s.mesh_hash) hull = &o.mesh->vertices;
        shapes.push_back(from_lcm(s, hull));
      }
      // The robot at the joints asked for: its links (and what it carries) join the shapes.
      if (!q.robot.empty() || q.n_joint_values > 0 || q.n_joint_names > 0) {
        if (q.type != artisan::query_t::COLLISION && q.type != artisan::query_t::DISTANCE)
          throw Error("a robot configuration goes with COLLISION and DISTANCE queries, not with query type " + std::to_string(int(q.type)));
        const std::string robot = q.robot == "*" ? "" : q.robot;
        const auto joints = world.joint_values(robot, q.joint_names, q.joint_values);
        for (auto& s : world.robot_shapes({robot, joints})) shapes.push_back(std::move(s));
      }
      std::vector<worldmodel::AllowedPair> allowed;
      for (const auto& a : q.allowed) allowed.push_back(from_lcm(a));
      auto add_contact = [&](const worldmodel::Contact& c) {
        artisan::contact_t m;
        m.shape = c.shape;
        m.object_id = c.body;
        for (int k = 0; k < 3; ++k) {
          m.point_on_shape[k] = c.point_on_shape[k];
          m.point_on_object[k] = c.point_on_body[k];
        }
        m.distance = c.distance_m;
        r.contacts.push_back(m);
      };
      switch (q.type) {
        case artisan::query_t::COLLISION: {
          const auto c = world.collision().check(shapes, allowed);
          r.in_collision = c.in_collision;
          for (const auto& x : c.contacts) add_contact(x);
          break;
        }
        case artisan::query_t::DISTANCE: {
          const auto d = world.collision().distance(shapes, q.max_distance, allowed);
          r.min_distance = d.distance_m;
          if (d.closest) add_contact(*d.closest);
          break;
        }
        case artisan::query_t::RAYCAST:
          for (const auto& ray : q.rays) {
            const auto h = world.collision().raycast({ray.origin[0], ray.origin[1], ray.origin[2]},
                                                     {ray.direction[0], ray.direction[1], ray.direction[2]}, ray.max_range);
            artisan::ray_hit_t m;
            m.hit = h.hit;
            m.object_id = h.body;
            for (int k = 0; k < 3; ++k) {
              m.point[k] = h.point[k];
              m.normal[k] = h.normal[k];
            }
            m.distance = h.distance_m;
            r.hits.push_back(m);
          }
          break;
        default: throw Error("unknown query type " + std::to_string(int(q.type)));
      }
    } catch (const std::exception& e) {
      r = artisan::query_reply_t();
      r.client_id = q.client_id;
      r.request_id = q.request_id;
      r.revision = world.revision();
      r.ok = false;
      r.error = e.what();
      ++stats.malformed_messages;
    }
    r.n_contacts = int32_t(r.contacts.size());
    r.n_hits = int32_t(r.hits.size());
    r.seconds = seconds_since(t0);
    r.utime = now_utime();
    lcm.publish(kQueryReplyChannel, &r);
    ++stats.queries_answered;
  }

  void on_command(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    artisan::command_t c;
    if (!decode(rbuf, c)) return error(channel, "cannot decode command_t (" + std::to_string(rbuf->data_size) + " bytes)");
    artisan::command_result_t r;
    r.client_id = c.client_id;
    r.request_id = c.request_id;
    r.object_id = c.object_id;
    const int64_t base = world.revision();
    try {
      switch (c.type) {
        case artisan::command_t::RERECOGNIZE: {
          const auto made = world.rerecognize();
          r.message = "recognized " + std::to_string(made.size()) + " object(s)";
          break;
        }
        case artisan::command_t::ACCEPT_POSE:
          world.accept_pose(c.object_id, c.author);
          r.message = "accepted the pose of " + world.find(c.object_id)->path;
          break;
        case artisan::command_t::CORRECT_POSE:
          world.correct_pose(c.object_id, from_lcm(c.pose, "corrected pose"), c.author);
          r.message = "corrected the pose of " + world.find(c.object_id)->path;
          break;
        case artisan::command_t::ATTACH:
          world.attach(c.object_id, c.attach_to, from_lcm(c.pose, "T_link_object"), c.author);
          r.message = "attached " + world.find(c.object_id)->path + " to " + c.attach_to;
          break;
        case artisan::command_t::DETACH:
          world.detach(c.object_id, c.author);
          r.message = "detached " + world.find(c.object_id)->path;
          break;
        case artisan::command_t::DELETE: {
          const std::string path = world.find(c.object_id) ? world.find(c.object_id)->path : "";
          world.remove_object(c.object_id, c.author);
          r.message = "deleted " + path;
          break;
        }
        case artisan::command_t::ADD: {
          const ObjectId id = world.add_object(c.model, from_lcm(c.pose, "new object's pose"), c.author);
          for (const auto& o : world.objects())
            if (o.version_id == id) r.object_id = o.object_id;
          r.message = "added " + world.find(r.object_id)->path;
          break;
        }
        default: throw Error("unknown command type " + std::to_string(int(c.type)));
      }
      r.ok = true;
      ++stats.commands_applied;
    } catch (const std::exception& e) {
      r.ok = false;
      r.message = e.what();
      ++stats.commands_refused;
    }
    // The edit refreshed the world model: tell everyone what changed.
    if (world.revision() != base) {
      publish_changes(base, world.last_changes());
      publish_snapshot();
    }
    r.revision = world.revision();
    r.utime = now_utime();
    lcm.publish(kCommandResultChannel, &r);
    poll_environment();  // starts the environment's re-cut, now that the diff is out
  }

  void heartbeat() {
    artisan::heartbeat_t h;
    h.utime = now_utime();
    h.service_id = options.service_id;
    h.status = status;
    h.folder = world.folder();
    h.revision = world.revision();
    h.n_objects = int32_t(world.objects().size());
    h.queries_answered = stats.queries_answered;
    h.malformed_messages = stats.malformed_messages;
    h.uptime_s = seconds_since(started);
    lcm.publish(kHeartbeatChannel, &h);
    last_heartbeat = Clock::now();
  }

  // The environment re-cut on the worker thread, once it is ready.
  void poll_environment() {
    const int64_t base = world.revision();
    try {
      const auto changes = world.poll_environment();
      if (changes.empty()) return;
      publish_changes(base, changes);
      publish_snapshot();
    } catch (const std::exception& e) {
      status = std::string("cannot re-cut the environment: ") + e.what();
    }
  }

  void tick() {
    poll_environment();
    if (seconds_since(last_poll) >= options.poll_period_s) {
      refresh();
      last_poll = Clock::now();
    }
    if (seconds_since(last_snapshot) >= options.snapshot_period_s) publish_snapshot();
    if (seconds_since(last_heartbeat) >= options.heartbeat_period_s) heartbeat();
  }
};

Service::Service(worldmodel::Workspace& workspace, lcm::LCM& lcm, ServiceOptions options)
    : impl_(std::make_unique<Impl>(workspace, lcm, std::move(options))) {
  auto& i = *impl_;
  i.subscriptions.push_back(lcm.subscribe(kMeshRequestChannel, &Impl::on_mesh_request, impl_.get()));
  i.subscriptions.push_back(lcm.subscribe(kQueryChannel, &Impl::on_query, impl_.get()));
  i.subscriptions.push_back(lcm.subscribe(kCommandChannel, &Impl::on_command, impl_.get()));
  i.publish_snapshot();
  i.publish_environment();
  i.heartbeat();
}

Service::~Service() {
  for (auto* s : impl_->subscriptions) impl_->lcm.unsubscribe(s);
}

void Service::tick() { impl_->tick(); }

void Service::run(const std::atomic<bool>& stop) {
  while (!stop) {
    impl_->lcm.handleTimeout(50);
    impl_->tick();
  }
}

const worldmodel::WorldModel& Service::world() const { return impl_->world; }
const ServiceStats& Service::stats() const { return impl_->stats; }
void Service::publish_snapshot() { impl_->publish_snapshot(); }

}  // namespace artisan::teleop
