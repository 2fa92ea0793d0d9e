#include "artisan/teleop_bridge/client.hpp"

#include <algorithm>
#include <chrono>
#include <random>
#include <set>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_format.hpp"
#include "artisan/mesh_chunk_t.hpp"
#include "artisan/mesh_request_t.hpp"
#include "artisan/scene_diff_t.hpp"
#include "artisan/scene_snapshot_t.hpp"
#include "artisan/teleop_bridge/channels.hpp"
#include "artisan/worldmodel/world_model.hpp"
#include "convert.hpp"

namespace artisan::teleop {
namespace {

using Clock = std::chrono::steady_clock;

Transform pose_or_identity(const artisan::pose_t& p) {
  try {
    return from_lcm(p, "pose");
  } catch (const Error&) {
    return Transform::Identity();
  }
}

}  // namespace

struct SceneClient::Impl {
  Impl(lcm::LCM& l, std::string id, std::function<void(int)> p) : lcm(l), client_id(std::move(id)), pump(std::move(p)) {}
  lcm::LCM& lcm;
  std::string client_id;
  std::function<void(int)> pump;
  std::vector<lcm::Subscription*> subscriptions;
  bool has_scene = false;
  int64_t revision = -1;
  std::string folder, service_id;
  std::map<int64_t, RemoteObject> objects;
  std::vector<artisan::robot_state_t> robots;
  std::map<std::string, std::shared_ptr<const TriangleMesh>> meshes;
  // A mesh being fetched: the chunks so far, and the ones asked for and not yet arrived.
  struct Transfer {
    std::vector<std::vector<uint8_t>> chunks;
    int received = 0;
    std::set<int32_t> in_flight;
    Clock::time_point asked{};
  };
  std::map<std::string, Transfer> transfers;
  std::map<int64_t, artisan::query_reply_t> replies;
  std::map<int64_t, artisan::command_result_t> results;
  int64_t next_request = 1;
  int64_t updates = 0;

  RemoteObject remote(const artisan::scene_object_t& o) {
    RemoteObject r;
    r.info = o;
    r.T_world_object = pose_or_identity(o.pose);
    for (const auto& g : o.grasps) r.T_world_grasps.push_back(pose_or_identity(g));
    r.T_world_alternative = pose_or_identity(o.alternative_pose);
    if (auto it = meshes.find(o.mesh.hash); it != meshes.end()) r.mesh = it->second;
    return r;
  }

  void on_snapshot(const lcm::ReceiveBuffer*, const std::string&, const artisan::scene_snapshot_t* s) {
    if (s->revision < revision && s->service_id == service_id) return;  // an old one
    objects.clear();
    for (const auto& o : s->objects) objects[o.object_id] = remote(o);
    robots = s->robots;
    revision = s->revision;
    folder = s->folder;
    service_id = s->service_id;
    has_scene = true;
    ++updates;
  }

  void on_diff(const lcm::ReceiveBuffer*, const std::string&, const artisan::scene_diff_t* d) {
    // A diff applies only on top of the revision it was made from; otherwise wait for the next
    // snapshot.
    if (!has_scene || d->base_revision != revision || d->service_id != service_id) return;
    for (const auto& o : d->changed) objects[o.object_id] = remote(o);
    for (int64_t id : d->removed) objects.erase(id);
    if (d->robots_changed) robots = d->robots;
    revision = d->revision;
    ++updates;
  }

  void on_chunk(const lcm::ReceiveBuffer*, const std::string&, const artisan::mesh_chunk_t* c) {
    if (meshes.count(c->hash)) return;
    // Chunks asked for by this client, or by another for a mesh this scene uses (a replayed log).
    const bool wanted = transfers.count(c->hash) || std::any_of(objects.begin(), objects.end(), [&](const auto& kv) {
                          return kv.second.info.mesh.hash == c->hash;
                        });
    if (!wanted) return;
    if (c->n_chunks <= 0 || c->chunk_index < 0 || c->chunk_index >= c->n_chunks) return;
    auto& t = transfers[c->hash];
    if (t.chunks.size() != size_t(c->n_chunks)) t = Transfer{std::vector<std::vector<uint8_t>>(size_t(c->n_chunks)), 0, {}, {}};
    t.in_flight.erase(c->chunk_index);
    if (!t.chunks[size_t(c->chunk_index)].empty()) return;
    t.chunks[size_t(c->chunk_index)] = c->data;
    if (++t.received < c->n_chunks) return;
    std::vector<uint8_t> bytes;
    for (const auto& ch : t.chunks) bytes.insert(bytes.end(), ch.begin(), ch.end());
    transfers.erase(c->hash);
    if (worldmodel::content_hash(bytes) != c->hash) return;  // corrupt: start again
    auto mesh = std::make_shared<const TriangleMesh>(io::decode_mesh(bytes, "mesh " + c->hash));
    meshes[c->hash] = mesh;
    for (auto& [id, o] : objects)
      if (o.info.mesh.hash == c->hash) o.mesh = mesh;
  }

  void on_reply(const lcm::ReceiveBuffer*, const std::string&, const artisan::query_reply_t* r) {
    if (r->client_id == client_id) replies[r->request_id] = *r;
  }
  void on_result(const lcm::ReceiveBuffer*, const std::string&, const artisan::command_result_t* r) {
    if (r->client_id == client_id) results[r->request_id] = *r;
  }

  // Asks for the next chunks of every mesh the scene uses and has not got: a window of chunks
  // at a time, the next window when these have arrived, and again what has not arrived after a
  // while (UDP may drop them). Returns whether any mesh is still missing.
  bool request_missing_meshes() {
    bool missing = false;
    for (const auto& [id, o] : objects) {
      const auto& h = o.info.mesh.hash;
      if (h.empty() || meshes.count(h)) continue;
      missing = true;
      auto& t = transfers[h];
      if (t.chunks.empty() && o.info.mesh.n_bytes > 0)
        t.chunks.resize(size_t((o.info.mesh.n_bytes + kMeshChunkBytes - 1) / kMeshChunkBytes));
      if (!t.in_flight.empty() && Clock::now() - t.asked < std::chrono::milliseconds(300)) continue;
      t.in_flight.clear();
      for (size_t i = 0; i < t.chunks.size() && t.in_flight.size() < size_t(kMeshChunkWindow); ++i)
        if (t.chunks[i].empty()) t.in_flight.insert(int32_t(i));
      artisan::mesh_request_t req;
      req.utime = now_utime();
      req.client_id = client_id;
      req.hash = h;
      req.chunks.assign(t.in_flight.begin(), t.in_flight.end());  // empty (all) if the size is unknown
      req.n_chunks = int32_t(req.chunks.size());
      if (req.chunks.empty()) t.in_flight.insert(-1);              // wait before asking for all again
      lcm.publish(kMeshRequestChannel, &req);
      t.asked = Clock::now();
    }
    return missing;
  }
};

SceneClient::SceneClient(lcm::LCM& lcm, std::string client_id, std::function<void(int)> pump)
    : impl_(std::make_unique<Impl>(lcm, std::move(client_id), std::move(pump))) {
  if (!lcm.good()) throw Error("LCM is not available (bad URL or no network)");
  if (!impl_->pump) impl_->pump = [&lcm](int ms) { lcm.handleTimeout(ms); };
  auto* i = impl_.get();
  i->subscriptions.push_back(lcm.subscribe(kSceneChannel, &Impl::on_snapshot, i));
  i->subscriptions.push_back(lcm.subscribe(kSceneDiffChannel, &Impl::on_diff, i));
  i->subscriptions.push_back(lcm.subscribe(kMeshChunkChannel, &Impl::on_chunk, i));
  i->subscriptions.push_back(lcm.subscribe(kQueryReplyChannel, &Impl::on_reply, i));
  i->subscriptions.push_back(lcm.subscribe(kCommandResultChannel, &Impl::on_result, i));
}

SceneClient::~SceneClient() {
  for (auto* s : impl_->subscriptions) impl_->lcm.unsubscribe(s);
}

void SceneClient::pump(int ms) { impl_->pump(ms); }

bool SceneClient::wait_for_scene(double timeout_s, bool with_meshes) {
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (Clock::now() < end) {
    if (impl_->has_scene && (!with_meshes || !impl_->request_missing_meshes())) return true;
    pump(20);
  }
  return impl_->has_scene && (!with_meshes || !impl_->request_missing_meshes());
}

bool SceneClient::wait_for_revision(int64_t revision, double timeout_s) {
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (impl_->revision < revision && Clock::now() < end) pump(20);
  return impl_->revision >= revision;
}

bool SceneClient::has_scene() const { return impl_->has_scene; }
int64_t SceneClient::revision() const { return impl_->revision; }
std::string SceneClient::folder() const { return impl_->folder; }
std::string SceneClient::service_id() const { return impl_->service_id; }
const std::map<int64_t, RemoteObject>& SceneClient::objects() const { return impl_->objects; }
const std::vector<artisan::robot_state_t>& SceneClient::robots() const { return impl_->robots; }

void SceneClient::set_robot(artisan::query_t& q, const std::string& robot, const std::map<std::string, double>& joints) {
  q.robot = robot.empty() ? "*" : robot;
  q.joint_names.clear();
  q.joint_values.clear();
  for (const auto& [name, value] : joints) {
    q.joint_names.push_back(name);
    q.joint_values.push_back(value);
  }
}
size_t SceneClient::meshes_fetched() const { return impl_->meshes.size(); }
int64_t SceneClient::updates_received() const { return impl_->updates; }

artisan::query_reply_t SceneClient::query(artisan::query_t q, double timeout_s) {
  q.client_id = impl_->client_id;
  q.request_id = impl_->next_request++;
  q.utime = now_utime();
  q.n_shapes = int32_t(q.shapes.size());
  q.n_allowed = int32_t(q.allowed.size());
  q.n_rays = int32_t(q.rays.size());
  q.n_joint_names = int32_t(q.joint_names.size());
  q.n_joint_values = int32_t(q.joint_values.size());
  impl_->lcm.publish(kQueryChannel, &q);
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (Clock::now() < end) {
    if (auto it = impl_->replies.find(q.request_id); it != impl_->replies.end()) {
      auto r = it->second;
      impl_->replies.erase(it);
      return r;
    }
    pump(5);
  }
  throw Error("no reply from the world-model service to query " + std::to_string(q.request_id) + " within " + std::to_string(timeout_s) + " s");
}

artisan::command_result_t SceneClient::command(artisan::command_t c, double timeout_s) {
  c.client_id = impl_->client_id;
  c.request_id = impl_->next_request++;
  c.utime = now_utime();
  impl_->lcm.publish(kCommandChannel, &c);
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (Clock::now() < end) {
    if (auto it = impl_->results.find(c.request_id); it != impl_->results.end()) {
      auto r = it->second;
      impl_->results.erase(it);
      return r;
    }
    pump(5);
  }
  throw Error("no answer from the world-model service to command " + std::to_string(c.request_id) + " within " + std::to_string(timeout_s) + " s");
}

}  // namespace artisan::teleop
