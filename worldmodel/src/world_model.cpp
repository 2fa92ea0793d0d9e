#include "artisan/worldmodel/world_model.hpp"

#include <algorithm>
#include <chrono>
#include <ctime>
#include <functional>
#include <set>

#include <sys/resource.h>
#include <unistd.h>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_format.hpp"
#include "artisan/perception/kdtree.hpp"
#include "artisan/worldmodel/multimesh.hpp"
#include "artisan/worldmodel/recognition_store.hpp"

namespace artisan::worldmodel {
namespace {

using json = nlohmann::json;

Transform transform_from_json(const json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 16) throw Error(what + ": expected 16 numbers (a row-major 4x4)");
  std::array<double, 16> a{};
  for (size_t k = 0; k < 16; ++k) a[k] = j[k].get<double>();
  return from_row_major(a);
}

std::string to_row_major_string(const Transform& T) {
  std::string s;
  char buf[32];
  for (double v : to_row_major(T)) {
    std::snprintf(buf, sizeof buf, "%.17g,", v);
    s += buf;
  }
  return s;
}

std::string utc_now() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

void walk(const Workspace& ws, ObjectId folder, std::vector<ObjectInfo>& out) {
  for (const auto& c : ws.children(folder)) {
    out.push_back(c);
    if (c.kind == ObjectKind::kFolder) walk(ws, c.id, out);
  }
}

ObjectId first_version(const Workspace& ws, const ObjectInfo& info) {
  return info.previous_version ? ws.versions(info.id).front().id : info.id;
}

using PlacedMesh = std::pair<std::shared_ptr<const TriangleMesh>, Transform>;

// Removes the triangles whose three vertices all lie within `distance` of the objects' surfaces
// (their vertices, with the half edge length of each model added), and unused vertices.
TriangleMesh cut_out(const TriangleMesh& environment, const std::vector<PlacedMesh>& objects, double distance) {
  if (objects.empty()) return environment;
  std::vector<Eigen::Vector3f> points;
  double reach = distance;
  for (const auto& [mesh, T_world_object] : objects) {
    const Eigen::Matrix4f T = T_world_object.matrix().cast<float>();
    for (const auto& v : mesh->vertices) points.push_back((T * v.homogeneous()).head<3>());
    reach = std::max(reach, distance + 0.5 * mesh->median_edge_length());
  }
  const KdTree3 tree(std::move(points));
  std::vector<char> near(environment.vertices.size());
  for (size_t i = 0; i < near.size(); ++i) near[i] = tree.nearest(environment.vertices[i]).second <= float(reach * reach);
  TriangleMesh out;
  std::vector<int> remap(environment.vertices.size(), -1);
  for (const auto& f : environment.faces) {
    if (near[f[0]] && near[f[1]] && near[f[2]]) continue;
    Eigen::Vector3i g;
    for (int k = 0; k < 3; ++k) {
      int& r = remap[f[k]];
      if (r < 0) {
        r = int(out.vertices.size());
        out.vertices.push_back(environment.vertices[f[k]]);
        if (!environment.normals.empty()) out.normals.push_back(environment.normals[f[k]]);
        if (!environment.colors.empty()) out.colors.push_back(environment.colors[f[k]]);
      }
      g[k] = r;
    }
    out.faces.push_back(g);
  }
  return out;
}

}  // namespace

std::string content_hash(const std::vector<uint8_t>& bytes) {
  uint64_t h = 1469598103934665603ull;
  for (uint8_t b : bytes) h = (h ^ b) * 1099511628211ull;
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

bool SceneObject::same_state(const SceneObject& o) const {
  return version_id == o.version_id && mesh_hash == o.mesh_hash && T_world_object.isApprox(o.T_world_object, 0) &&
         status == o.status && attached_to == o.attached_to;
}

struct WorldModel::Loaded {
  std::vector<SceneObject> objects;
  int64_t newest_row = 0;
};

// The environment less the objects' surface: its inputs, and what the cut made of them.
struct WorldModel::EnvironmentCut {
  std::string signature;        ///< of the environment meshes and the objects cut out
  std::string whole_signature;  ///< of the environment meshes alone
  std::shared_ptr<const TriangleMesh> whole;
  std::vector<PlacedMesh> objects;
  double cutout_distance_m = 0;

  std::shared_ptr<const TriangleMesh> mesh;
  std::vector<uint8_t> encoded;  ///< with hash and geometry: made only off the main thread
  std::string hash;
  std::shared_ptr<const BodyGeometry> geometry;

  void run(bool everything) {
    mesh = std::make_shared<const TriangleMesh>(cut_out(*whole, objects, cutout_distance_m));
    if (!everything) return;
    encoded = io::encode_mesh(*mesh);
    hash = content_hash(encoded);
    geometry = CollisionScene::build_geometry(mesh);
  }
};

WorldModel::WorldModel(Workspace& workspace, std::string folder, WorldModelOptions options)
    : ws_(workspace), folder_(std::move(folder)), options_(options), collision_(std::make_unique<CollisionScene>()) {
  ws_.folder(folder_);  // throws when it is not a folder
  refresh();
}

WorldModel::~WorldModel() = default;

WorldModel::Loaded WorldModel::load() {
  Loaded out;
  std::vector<ObjectInfo> all;
  walk(ws_, ws_.folder(folder_).id, all);
  for (const auto& o : all) out.newest_row = std::max(out.newest_row, o.id);

  // Where each mesh sits in the world, and which meshes make the environment.
  std::vector<std::pair<ObjectInfo, Transform>> environment;
  std::map<ObjectId, Transform> T_world_mesh;
  for (const auto& o : all)
    if (o.kind == ObjectKind::kMesh && o.subkind == "merged") environment.emplace_back(o, Transform::Identity());
  const ObjectInfo* newest_multimesh = nullptr;
  for (const auto& o : all)
    if (o.kind == ObjectKind::kMultiMesh && (!newest_multimesh || o.id > newest_multimesh->id)) newest_multimesh = &o;
  if (newest_multimesh) {
    const auto members = ws_.members(newest_multimesh->id);
    const auto T_root = root_transforms(members);
    for (const auto& m : members) {
      T_world_mesh[m.mesh] = T_root.at(m.member_id);
      if (environment.empty() || environment.front().first.subkind != "merged") environment.emplace_back(ws_.get(m.mesh), T_root.at(m.member_id));
    }
  }
  if (environment.empty())
    for (const auto& o : all)
      if (o.kind == ObjectKind::kMesh) environment.emplace_back(o, Transform::Identity());

  // Recognized objects.
  std::map<ObjectId, ObjectInfo> models;
  for (const auto& o : all) {
    if (o.kind != ObjectKind::kRecognizedModel) continue;
    const auto& md = o.metadata;
    const std::string status = md.value("status", std::string("recognized"));
    if (status == "deleted") continue;
    SceneObject s;
    s.object_id = first_version(ws_, o);
    s.version_id = o.id;
    s.version = o.version;
    s.path = o.path;
    s.kind = SceneObject::Kind::object;
    s.status = status;
    s.model_id = md.at("model_id").get<ObjectId>();
    if (!models.count(s.model_id)) models[s.model_id] = ws_.get(s.model_id);
    const auto& model = models[s.model_id];
    s.model = model.name;
    if (md.contains("T_world_object")) {
      s.T_world_object = transform_from_json(md["T_world_object"], o.path);
    } else {
      Transform T_world_scene = Transform::Identity();
      if (const auto prov = ws_.provenance(o.id); prov && !prov->inputs.empty())
        if (auto it = T_world_mesh.find(prov->inputs.front()); it != T_world_mesh.end()) T_world_scene = it->second;
      s.T_world_object = T_world_scene * transform_from_json(md.at("T_scene_model"), o.path);
    }
    if (md.contains("figures")) {
      s.score = md["figures"].value("score", 0.0);
      s.overlap = md["figures"].value("overlap", 0.0);
      s.ambiguous = md["figures"].value("ambiguous", false);
    }
    if (model.metadata.contains("T_model_grasps"))
      for (const auto& g : model.metadata["T_model_grasps"]) s.T_world_grasps.push_back(s.T_world_object * transform_from_json(g, model.path));
    if (md.contains("attached_to")) {
      s.attached_to = md["attached_to"].get<std::string>();
      s.T_link_object = transform_from_json(md.at("T_link_object"), o.path);
    }
    s.margin_m = options_.object_margin_m;
    auto& mesh = model_meshes_[s.model_id];
    if (!mesh) mesh = std::make_shared<const TriangleMesh>(ws_.load_mesh(s.model_id));
    s.mesh = mesh;
    out.objects.push_back(std::move(s));
  }

  // The environment: its meshes in the world frame, less the recognized objects' surface.
  if (!environment.empty()) {
    SceneObject env;
    env.kind = SceneObject::Kind::environment;
    env.status = "environment";
    env.object_id = first_version(ws_, environment.front().first);
    env.version_id = environment.front().first.id;
    env.version = environment.front().first.version;
    env.path = environment.front().first.path;
    env.margin_m = options_.environment_margin_m;
    // Rebuilt only when its meshes or the objects cut out of it changed; in the background when
    // only objects did.
    std::string whole_signature;
    for (const auto& [info, T] : environment) whole_signature += std::to_string(info.id) + to_row_major_string(T) + ";";
    auto cut = std::make_shared<EnvironmentCut>();
    cut->whole_signature = whole_signature;
    cut->signature = whole_signature + "|";
    for (const auto& s : out.objects) {
      cut->signature += std::to_string(s.version_id) + to_row_major_string(s.T_world_object) + ";";
      cut->objects.emplace_back(s.mesh, s.T_world_object);
    }
    cut->cutout_distance_m = options_.cutout_distance_m;
    bool new_whole = false;
    if (whole_signature != whole_signature_ || !whole_environment_) {
      TriangleMesh whole;
      for (const auto& [info, T] : environment) {
        TriangleMesh m = ws_.load_mesh(info.id);
        m.transform(T);
        if (m.normals.empty()) m.compute_vertex_normals();
        whole.append(m);
      }
      whole_environment_ = std::make_shared<const TriangleMesh>(std::move(whole));
      whole_signature_ = whole_signature;
      new_whole = true;
    }
    cut->whole = whole_environment_;
    if (cut->signature != environment_signature_ || !environment_mesh_) {
      if (!options_.environment_in_background || new_whole || !environment_mesh_) {
        cut->run(false);
        environment_mesh_ = cut->mesh;
        environment_signature_ = cut->signature;
      }
    }
    latest_ = std::move(cut);
    env.mesh = environment_mesh_;
    out.objects.insert(out.objects.begin(), std::move(env));
  }
  return out;
}

SceneChanges WorldModel::refresh() {
  Loaded loaded = load();
  SceneChanges changes;
  std::map<ObjectId, const SceneObject*> before;
  for (const auto& o : objects_) before[o.object_id] = &o;
  std::set<ObjectId> now;
  for (auto& o : loaded.objects) {
    now.insert(o.object_id);
    // Encode (and hash) each distinct mesh once.
    const auto old = before.find(o.object_id);
    const auto same_mesh = std::find_if(objects_.begin(), objects_.end(), [&](const SceneObject& x) { return x.mesh == o.mesh; });
    if (same_mesh != objects_.end()) {
      o.mesh_hash = same_mesh->mesh_hash;
    } else {
      auto bytes = io::encode_mesh(*o.mesh);
      o.mesh_hash = content_hash(bytes);
      encoded_.try_emplace(o.mesh_hash, std::move(bytes));
    }
    if (old != before.end() && old->second->same_state(o) && old->second->mesh_hash == o.mesh_hash) {
      o.mesh = old->second->mesh;  // keep the pointer so the collision hierarchy is reused
      continue;
    }
    changes.changed.push_back(o.object_id);
    // Attached objects travel with the robot, not with the static scene.
    if (!o.attached_to.empty()) collision_->remove(o.object_id);
    else if (old != before.end() && old->second->mesh == o.mesh && collision_->contains(o.object_id))
      collision_->set_pose(o.object_id, o.T_world_object);
    else
      collision_->set_body(o.object_id, o.mesh, o.T_world_object, o.margin_m);
  }
  for (const auto& [id, o] : before)
    if (!now.count(id)) {
      changes.removed.push_back(id);
      collision_->remove(id);
    }
  objects_ = std::move(loaded.objects);
  // Forget encodings no object uses any more.
  std::set<std::string> used;
  for (const auto& o : objects_) used.insert(o.mesh_hash);
  std::erase_if(encoded_, [&](const auto& kv) { return !used.count(kv.first); });
  // Row x 1000 + changes since that row (background re-cuts): a fresh start takes the top of its
  // row's range, above anything an earlier run reached from the same rows.
  constexpr int64_t kPerRow = 1000;
  if (revision_ == 0) revision_ = loaded.newest_row * kPerRow + kPerRow - 1;
  else if (!changes.empty()) revision_ = std::max(revision_ + 1, loaded.newest_row * kPerRow);
  last_changes_ = changes;
  return changes;
}

void WorldModel::start_environment_job() {
  if (job_.valid() || !latest_ || latest_->signature == environment_signature_ || !options_.environment_in_background) return;
  job_ = std::async(std::launch::async, [cut = *latest_]() mutable {
    // Below the thread that serves queries and edits: on a busy machine they come first.
    setpriority(PRIO_PROCESS, pid_t(::gettid()), 10);
    cut.run(true);
    return std::make_unique<EnvironmentCut>(std::move(cut));
  });
}

SceneChanges WorldModel::poll_environment(bool wait) {
  SceneChanges changes;
  if (job_.valid() && (wait || job_.wait_for(std::chrono::seconds(0)) == std::future_status::ready)) {
    const auto cut = job_.get();
    // Made from the environment meshes still in use: at least as new as the cut in place.
    auto env = std::find_if(objects_.begin(), objects_.end(), [](const SceneObject& o) { return o.kind == SceneObject::Kind::environment; });
    if (cut->whole_signature == whole_signature_ && cut->signature != environment_signature_ && env != objects_.end()) {
      environment_mesh_ = cut->mesh;
      environment_signature_ = cut->signature;
      encoded_.try_emplace(cut->hash, std::move(cut->encoded));
      env->mesh = cut->mesh;
      env->mesh_hash = cut->hash;
      collision_->set_body(env->object_id, cut->geometry, env->T_world_object, env->margin_m);
      changes.changed.push_back(env->object_id);
      std::set<std::string> used;
      for (const auto& o : objects_) used.insert(o.mesh_hash);
      std::erase_if(encoded_, [&](const auto& kv) { return !used.count(kv.first); });
      ++revision_;
      last_changes_ = changes;
    }
  }
  start_environment_job();  // objects moved again meanwhile
  return changes;
}

const SceneObject* WorldModel::find(ObjectId object_id) const {
  for (const auto& o : objects_)
    if (o.object_id == object_id) return &o;
  return nullptr;
}

const SceneObject& WorldModel::object_or_throw(ObjectId object_id) const {
  const auto* o = find(object_id);
  if (!o) throw Error("the world model of " + folder_ + " has no object " + std::to_string(object_id));
  if (o->kind != SceneObject::Kind::object) throw Error(o->path + " is the environment, not an object that can be edited");
  return *o;
}

const std::vector<uint8_t>& WorldModel::encoded_mesh(const std::string& hash) const {
  auto it = encoded_.find(hash);
  if (it == encoded_.end()) throw Error("the world model has no mesh with hash '" + hash + "'");
  return it->second;
}

ObjectId WorldModel::edit(ObjectId object_id, const std::string& action, const std::string& author, json changes) {
  if (author.empty()) throw Error("an edit needs an author");
  const auto& o = object_or_throw(object_id);
  const auto info = ws_.get(o.version_id);
  NewObject next;
  next.kind = info.kind;
  next.subkind = info.subkind;
  next.name = info.name;
  next.metadata = info.metadata;
  for (auto& [k, v] : changes.items()) {
    if (v.is_null()) next.metadata.erase(k);
    else next.metadata[k] = v;
  }
  next.metadata["edit"] = {{"action", action}, {"author", author}, {"at", utc_now()}};
  next.provenance = Provenance{"operator-edit", {{"action", action}, {"author", author}}, {o.version_id}};
  const ObjectId id = ws_.add_version(o.version_id, next);
  refresh();
  return id;
}

ObjectId WorldModel::correct_pose(ObjectId object_id, const Transform& T_world_object, const std::string& author) {
  if (!T_world_object.matrix().allFinite()) throw Error("correct pose: the pose is not finite");
  return edit(object_id, "correct-pose", author, {{"T_world_object", to_row_major(T_world_object)}, {"status", "corrected"}});
}

ObjectId WorldModel::accept_pose(ObjectId object_id, const std::string& author) {
  return edit(object_id, "accept-pose", author, {{"status", "accepted"}});
}

ObjectId WorldModel::attach(ObjectId object_id, const std::string& link, const Transform& T_link_object, const std::string& author) {
  if (link.empty()) throw Error("attach: name the link the object is attached to");
  if (!T_link_object.matrix().allFinite()) throw Error("attach: the pose is not finite");
  return edit(object_id, "attach", author, {{"attached_to", link}, {"T_link_object", to_row_major(T_link_object)}});
}

ObjectId WorldModel::detach(ObjectId object_id, const std::string& author) {
  if (object_or_throw(object_id).attached_to.empty()) throw Error(find(object_id)->path + " is not attached");
  return edit(object_id, "detach", author, {{"attached_to", nullptr}, {"T_link_object", nullptr}});
}

ObjectId WorldModel::remove_object(ObjectId object_id, const std::string& author) {
  return edit(object_id, "delete", author, {{"status", "deleted"}});
}

ObjectId WorldModel::add_object(const std::string& model, const Transform& T_world_object, const std::string& author) {
  if (author.empty()) throw Error("an edit needs an author");
  if (!T_world_object.matrix().allFinite()) throw Error("add object: the pose is not finite");
  std::optional<ObjectInfo> m;
  if (!model.empty() && (model[0] == '/' || std::all_of(model.begin(), model.end(), ::isdigit))) {
    m = ws_.resolve(model);
  } else {
    std::vector<ObjectInfo> all;
    walk(ws_, ws_.root(), all);
    for (const auto& o : all)
      if (o.kind == ObjectKind::kModel && o.name == model) m = o;
  }
  if (!m) throw Error("add object: no model named '" + model + "'");
  if (m->kind != ObjectKind::kModel) throw Error("add object: " + m->path + " is a " + to_string(m->kind) + ", not a model");
  const ObjectId folder = ws_.folder(folder_).id;
  std::set<std::string> names;
  for (const auto& c : ws_.children(folder)) names.insert(c.name);
  int n = 1;
  while (names.count(m->name + "-added-" + std::to_string(n))) ++n;
  NewObject o;
  o.kind = ObjectKind::kRecognizedModel;
  o.subkind = m->name;
  o.name = m->name + "-added-" + std::to_string(n);
  o.metadata = {{"model", m->path},
                {"model_id", m->id},
                {"T_world_object", to_row_major(T_world_object)},
                {"status", "added"},
                {"edit", {{"action", "add"}, {"author", author}, {"at", utc_now()}}}};
  o.provenance = Provenance{"operator-add", {{"author", author}}, {m->id}};
  const ObjectId id = ws_.add(folder, o);
  refresh();
  return id;
}

std::vector<ObjectId> WorldModel::rerecognize() {
  std::vector<ObjectInfo> all;
  walk(ws_, ws_.folder(folder_).id, all);
  std::vector<ObjectId> scenes;
  for (const auto& o : all)
    if (o.kind == ObjectKind::kMesh && o.subkind == "merged") scenes.push_back(o.id);
  if (scenes.empty())
    for (const auto& o : all)
      if (o.kind == ObjectKind::kMesh) scenes.push_back(o.id);
  if (scenes.empty()) throw Error("re-recognize: " + folder_ + " has no mesh to recognize objects in");
  std::vector<ObjectId> made;
  for (ObjectId s : scenes)
    for (const auto& r : recognize_models(ws_, s, {})) made.push_back(r.id);
  refresh();
  return made;
}

}  // namespace artisan::worldmodel
