#include "artisan/worldmodel/world_model.hpp"

#include <algorithm>
#include <chrono>
#include <ctime>
#include <functional>
#include <optional>
#include <set>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_format.hpp"
#include "artisan/core/scheduling.hpp"
#include "artisan/perception/kdtree.hpp"
#include "artisan/perception/spin_image.hpp"
#include "artisan/worldmodel/multimesh.hpp"
#include "artisan/worldmodel/recognition_store.hpp"
#include "artisan/worldmodel/robot_store.hpp"
#include "utc_time.hpp"

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


void walk(const Workspace& ws, ObjectId folder, std::vector<ObjectInfo>& out) {
  for (const auto& c : ws.children(folder)) {
    out.push_back(c);
    if (c.kind == ObjectKind::kFolder) walk(ws, c.id, out);
  }
}


// Where a mesh's sensor was in the world, when the image it was meshed from knows it (image
// metadata sensor.T_world_sensor, written by the simulator, the sensor server and imports with a
// pose), else the pose the mesh carries itself (T_world_mesh).
std::optional<Transform> sensor_pose_of_mesh(const Workspace& ws, const ObjectInfo& mesh) {
  if (const auto prov = ws.provenance(mesh.id); prov && prov->operation == "mesh" && !prov->inputs.empty()) {
    const auto image = ws.get(prov->inputs.front());
    if (image.kind == ObjectKind::kImage && image.metadata.contains("sensor") && image.metadata["sensor"].contains("T_world_sensor"))
      return transform_from_json(image.metadata["sensor"]["T_world_sensor"], image.path + ": sensor.T_world_sensor");
  }
  if (mesh.metadata.contains("T_world_mesh")) return transform_from_json(mesh.metadata["T_world_mesh"], mesh.path + ": T_world_mesh");
  return std::nullopt;
}

// "ROBOT/LINK" split at the first '/'.
std::pair<std::string, std::string> robot_and_link(const std::string& attached_to) {
  const auto slash = attached_to.find('/');
  if (slash == std::string::npos) return {attached_to, ""};
  return {attached_to.substr(0, slash), attached_to.substr(slash + 1)};
}

using PlacedMesh = std::pair<std::shared_ptr<const TriangleMesh>, Transform>;

// Removes the triangles whose three vertices all lie within `distance` of the objects' surfaces,
// and unused vertices. The surfaces are sampled every `distance` (CAD models' vertices alone are
// too sparse: a long pipe is a few long triangles), so a point of a surface is within
// distance / sqrt(2) of a sample and the test reaches distance * (1 + 1 / sqrt(2)).
TriangleMesh cut_out(const TriangleMesh& environment, const std::vector<PlacedMesh>& objects, double distance) {
  if (objects.empty()) return environment;
  std::vector<Eigen::Vector3f> points;
  const double spacing = std::max(distance, 1e-4);
  const double reach = distance + spacing / std::sqrt(2.0);
  for (const auto& [mesh, T_world_object] : objects) {
    const Eigen::Matrix4f T = T_world_object.matrix().cast<float>();
    for (const auto& v : mesh->vertices) points.push_back((T * v.homogeneous()).head<3>());
    if (!mesh->faces.empty())
      for (const auto& v : sample_surface(*mesh, spacing).points) points.push_back((T * v.homogeneous()).head<3>());
  }
  const KdTree3 tree(std::move(points));
  std::vector<char> near(environment.vertices.size());
  for (size_t i = 0; i < near.size(); ++i) near[i] = tree.nearest_within(environment.vertices[i], float(reach)).has_value();
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
  std::vector<SceneRobot> robots;
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

ObjectId WorldModel::first_version(const ObjectInfo& info) {
  if (!info.previous_version) return info.id;
  auto it = first_versions_.find(info.id);
  if (it == first_versions_.end()) it = first_versions_.emplace(info.id, ws_.versions(info.id).front().id).first;
  return it->second;
}

SceneObject WorldModel::scene_object(const ObjectInfo& o, const std::map<ObjectId, Transform>& T_world_mesh,
                                     const std::vector<SceneRobot>& robots) {
  const auto& md = o.metadata;
  SceneObject s;
  s.object_id = first_version(o);
  s.version_id = o.id;
  s.version = o.version;
  s.path = o.path;
  s.kind = SceneObject::Kind::object;
  s.status = md.value("status", std::string("recognized"));
  s.model_id = md.at("model_id").get<ObjectId>();
  auto model_it = model_infos_.find(s.model_id);
  if (model_it == model_infos_.end()) model_it = model_infos_.emplace(s.model_id, ws_.get(s.model_id)).first;
  const auto& model = model_it->second;
  s.model = model.name;
  // Where the scene the object was recognized in lies (identity for one added by an operator);
  // looked up only when needed (an object an operator placed has its world pose stored), once.
  std::optional<Transform> world_scene;
  const auto T_world_scene = [&]() -> const Transform& {
    if (!world_scene) {
      world_scene = Transform::Identity();
      if (const auto prov = ws_.provenance(o.id); prov && !prov->inputs.empty())
        if (auto it = T_world_mesh.find(prov->inputs.front()); it != T_world_mesh.end()) world_scene = it->second;
    }
    return *world_scene;
  };
  if (md.contains("T_world_object")) s.T_world_object = transform_from_json(md["T_world_object"], o.path);
  else s.T_world_object = T_world_scene() * transform_from_json(md.at("T_scene_model"), o.path);
  if (md.contains("figures")) {
    s.score = md["figures"].value("score", 0.0);
    s.overlap = md["figures"].value("overlap", 0.0);
    s.ambiguous = md["figures"].value("ambiguous", false);
    // The recognizer's alternative, where it stored one (it did not before alternatives across
    // models), in the world as recognized (an operator's correction moves the object, not it).
    if (s.ambiguous && md["figures"].contains("alternative_model") && md.contains("T_scene_model_alternative")) {
      s.alternative_model = md["figures"]["alternative_model"].get<std::string>();
      s.T_world_alternative = T_world_scene() * transform_from_json(md["T_scene_model_alternative"], o.path + ": T_scene_model_alternative");
    }
  }
  if (model.metadata.contains("T_model_grasps"))
    for (const auto& g : model.metadata["T_model_grasps"]) s.T_world_grasps.push_back(s.T_world_object * transform_from_json(g, model.path));
  if (md.contains("attached_to")) {
    s.attached_to = md["attached_to"].get<std::string>();
    s.T_link_object = transform_from_json(md.at("T_link_object"), o.path);
    // Carried by a robot of the scene: where its link is now.
    const auto [robot_name, link] = robot_and_link(s.attached_to);
    for (const auto& r : robots)
      if (r.name == robot_name && r.T_world_links.count(link)) {
        const Transform T_world_object = r.T_world_links.at(link) * s.T_link_object;
        for (auto& g : s.T_world_grasps) g = T_world_object * s.T_world_object.inverse() * g;
        s.T_world_object = T_world_object;
      }
  }
  s.margin_m = options_.object_margin_m;
  auto& mesh = model_meshes_[s.model_id];
  if (!mesh) mesh = std::make_shared<const TriangleMesh>(ws_.load_mesh(s.model_id));
  s.mesh = mesh;
  return s;
}

WorldModel::Loaded WorldModel::load() {
  Loaded out;
  std::vector<ObjectInfo> all;
  walk(ws_, ws_.folder(folder_).id, all);
  for (const auto& o : all) out.newest_row = std::max(out.newest_row, o.id);

  // Where each mesh sits in the world, and which meshes make the environment.
  std::map<ObjectId, Transform> T_world_root;  // of each MultiMesh: its root member's sensor pose, else the identity
  const auto multimesh_pose = [&](ObjectId multimesh) {
    if (auto it = T_world_root.find(multimesh); it != T_world_root.end()) return it->second;
    Transform T = Transform::Identity();
    for (const auto& m : ws_.members(multimesh))
      if (!m.parent_member) {
        if (const auto pose = sensor_pose_of_mesh(ws_, ws_.get(m.mesh))) T = *pose;
        break;
      }
    return T_world_root[multimesh] = T;
  };
  std::vector<std::pair<ObjectInfo, Transform>> environment;
  std::map<ObjectId, Transform> T_world_mesh;
  for (const auto& o : all)
    if (o.kind == ObjectKind::kMesh && o.subkind == "merged") {
      // A merge of a MultiMesh is in its root member's frame.
      Transform T = Transform::Identity();
      if (const auto prov = ws_.provenance(o.id); prov && prov->operation == "merge" && prov->parameters.contains("multimesh"))
        T = multimesh_pose(prov->parameters["multimesh"].get<ObjectId>());
      environment.emplace_back(o, T);
      T_world_mesh[o.id] = T;
    }
  const bool have_merged = !environment.empty();
  const ObjectInfo* newest_multimesh = nullptr;
  for (const auto& o : all)
    if (o.kind == ObjectKind::kMultiMesh && (!newest_multimesh || o.id > newest_multimesh->id)) newest_multimesh = &o;
  if (newest_multimesh) {
    const auto members = ws_.members(newest_multimesh->id);
    const auto T_root = root_transforms(members);
    const Transform T_world_mm = multimesh_pose(newest_multimesh->id);
    for (const auto& m : members) {
      const Transform T = T_world_mm * T_root.at(m.member_id);
      T_world_mesh[m.mesh] = T;
      if (!have_merged) environment.emplace_back(ws_.get(m.mesh), T);
    }
  }
  if (environment.empty())
    for (const auto& o : all)
      if (o.kind == ObjectKind::kMesh) {
        const Transform T = sensor_pose_of_mesh(ws_, o).value_or(Transform::Identity());
        environment.emplace_back(o, T);
        T_world_mesh[o.id] = T;
      }

  // Robots at their current joints.
  for (const auto& o : all) {
    if (o.kind != ObjectKind::kRobot) continue;
    auto it = robot_versions_.find(o.id);
    if (it == robot_versions_.end()) {
      const auto stored = load_robot(ws_, o.id);
      SceneRobot r;
      r.object_id = first_version(o);
      r.version_id = o.id;
      r.version = o.version;
      r.name = o.name;
      r.path = o.path;
      r.model = stored.model;
      r.T_world_root = stored.T_world_root;
      r.joints = stored.joints;
      r.T_world_links = r.model->link_poses(r.joints, r.T_world_root);
      it = robot_versions_.emplace(o.id, std::move(r)).first;
    }
    out.robots.push_back(it->second);
  }
  std::erase_if(robot_versions_, [&](const auto& kv) {
    return std::none_of(out.robots.begin(), out.robots.end(), [&](const SceneRobot& r) { return r.version_id == kv.first; });
  });

  // Recognized objects.
  for (const auto& o : all) {
    if (o.kind != ObjectKind::kRecognizedModel) continue;
    if (o.metadata.value("status", std::string("recognized")) == "deleted") continue;
    out.objects.push_back(scene_object(o, T_world_mesh, out.robots));
  }

  // The environment: its meshes in the world frame, less the recognized objects' surface.
  if (!environment.empty()) {
    SceneObject env;
    env.kind = SceneObject::Kind::environment;
    env.status = "environment";
    env.object_id = first_version(environment.front().first);
    env.version_id = environment.front().first.id;
    env.version = environment.front().first.version;
    env.path = environment.front().first.path;
    env.margin_m = options_.environment_margin_m;
    // Rebuilt only when its meshes or the objects cut out of it changed; in the background when
    // only objects did.
    std::string whole_signature;
    for (const auto& [info, T] : environment) whole_signature += std::to_string(info.id) + to_row_major_string(T) + ";";
    auto cut = make_cut(whole_signature, out.objects, out.robots);
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

std::shared_ptr<WorldModel::EnvironmentCut> WorldModel::make_cut(const std::string& whole_signature, const std::vector<SceneObject>& objects,
                                                                  const std::vector<SceneRobot>& robots) const {
  auto cut = std::make_shared<EnvironmentCut>();
  cut->whole_signature = whole_signature;
  cut->signature = whole_signature + "|";
  for (const auto& s : objects) {
    if (s.kind != SceneObject::Kind::object) continue;
    cut->signature += std::to_string(s.version_id) + to_row_major_string(s.T_world_object) + ";";
    cut->objects.emplace_back(s.mesh, s.T_world_object);
  }
  if (options_.cut_out_robots)
    for (const auto& r : robots)
      for (const auto& [link, mesh] : r.model->link_meshes()) {
        cut->signature += "robot" + std::to_string(r.version_id) + "/" + link + ";";
        cut->objects.emplace_back(mesh, r.T_world_links.at(link));
      }
  cut->cutout_distance_m = options_.cutout_distance_m;
  cut->whole = whole_environment_;
  return cut;
}

std::string WorldModel::mesh_hash(const std::shared_ptr<const TriangleMesh>& mesh) {
  const auto same_mesh = std::find_if(objects_.begin(), objects_.end(), [&](const SceneObject& x) { return x.mesh == mesh; });
  if (same_mesh != objects_.end()) return same_mesh->mesh_hash;
  auto bytes = io::encode_mesh(*mesh);
  std::string hash = content_hash(bytes);
  encoded_.try_emplace(hash, std::move(bytes));
  return hash;
}

SceneChanges WorldModel::refresh() {
  const auto stamp = ws_.change_stamp();  // before the read: a commit during it is seen next time
  Loaded loaded = load();
  read_ = stamp;
  SceneChanges changes;
  std::map<ObjectId, const SceneObject*> before;
  for (const auto& o : objects_) before[o.object_id] = &o;
  std::set<ObjectId> now;
  for (auto& o : loaded.objects) {
    now.insert(o.object_id);
    // Encode (and hash) each distinct mesh once.
    const auto old = before.find(o.object_id);
    o.mesh_hash = mesh_hash(o.mesh);
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
  // Robots: a new version is a change (pose, joints or description).
  const auto versions = [](const std::vector<SceneRobot>& rs) {
    std::vector<ObjectId> v;
    for (const auto& r : rs) v.push_back(r.version_id);
    return v;
  };
  changes.robots = versions(robots_) != versions(loaded.robots);
  robots_ = std::move(loaded.robots);
  // The hulls of carried objects, once per mesh.
  std::map<const TriangleMesh*, std::pair<std::shared_ptr<const TriangleMesh>, std::vector<Eigen::Vector3f>>> hulls;
  for (const auto& o : objects_) {
    if (o.attached_to.empty() || hulls.count(o.mesh.get())) continue;
    auto it = attached_hulls_.find(o.mesh.get());
    hulls[o.mesh.get()] = it != attached_hulls_.end() ? it->second : std::make_pair(o.mesh, convex_hull_vertices(o.mesh->vertices));
  }
  attached_hulls_ = std::move(hulls);
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
    run_in_background();  // below the thread that serves queries and edits
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
      // The environment it replaces (mesh, hierarchy, encoding: tens of megabytes for millions of
      // triangles) is freed on another thread: unmapping that much takes milliseconds, which the
      // diff to clients should not wait for.
      std::vector<std::shared_ptr<const void>> garbage = {environment_mesh_, collision_->geometry(env->object_id)};
      environment_mesh_ = cut->mesh;
      environment_signature_ = cut->signature;
      encoded_.try_emplace(cut->hash, std::move(cut->encoded));
      env->mesh = cut->mesh;
      env->mesh_hash = cut->hash;
      collision_->set_body(env->object_id, cut->geometry, env->T_world_object, env->margin_m);
      changes.changed.push_back(env->object_id);
      std::set<std::string> used;
      for (const auto& o : objects_) used.insert(o.mesh_hash);
      for (auto it = encoded_.begin(); it != encoded_.end();) {
        if (used.count(it->first)) {
          ++it;
          continue;
        }
        garbage.push_back(std::make_shared<const std::vector<uint8_t>>(std::move(it->second)));
        it = encoded_.erase(it);
      }
      release(std::move(garbage));
      ++revision_;
      last_changes_ = changes;
    }
  }
  start_environment_job();  // objects moved again meanwhile
  return changes;
}

void WorldModel::release(std::vector<std::shared_ptr<const void>> garbage) {
  if (release_.valid()) release_.wait();  // the previous batch: long gone by now
  release_ = std::async(std::launch::async, [garbage = std::move(garbage)]() mutable {
    run_in_background();
    garbage.clear();
  });
}

const SceneRobot& WorldModel::robot(const std::string& name) const {
  std::string names;
  for (const auto& r : robots_) {
    if (r.name == name || (name.empty() && robots_.size() == 1)) return r;
    names += (names.empty() ? "" : ", ") + r.name;
  }
  if (robots_.empty()) throw Error("the world model of " + folder_ + " has no robot (add one with `artisan robot set`)");
  if (name.empty()) throw Error("the world model of " + folder_ + " has " + std::to_string(robots_.size()) + " robots (" + names + "): name one");
  throw Error("the world model of " + folder_ + " has no robot '" + name + "' (its robots: " + names + ")");
}

std::map<std::string, double> WorldModel::joint_values(const std::string& robot_name, const std::vector<std::string>& names,
                                                       const std::vector<double>& values) const {
  const auto& r = robot(robot_name);
  const auto joint_names = r.model->joint_names();
  std::string listed;
  for (const auto& n : joint_names) listed += (listed.empty() ? "" : ", ") + n;
  std::map<std::string, double> q;
  if (names.empty() && values.empty()) return q;  // the current joints
  if (names.empty()) {
    if (values.size() != joint_names.size())
      throw Error("robot '" + r.name + "' has " + std::to_string(joint_names.size()) + " joints (" + listed + "), got " +
                  std::to_string(values.size()) + " joint value(s) and no joint names");
    for (size_t k = 0; k < values.size(); ++k) q[joint_names[k]] = values[k];
  } else {
    if (values.size() != names.size())
      throw Error("robot '" + r.name + "': " + std::to_string(names.size()) + " joint name(s) but " + std::to_string(values.size()) +
                  " joint value(s)");
    for (size_t k = 0; k < names.size(); ++k)
      if (!q.emplace(names[k], values[k]).second) throw Error("robot '" + r.name + "': joint '" + names[k] + "' is given twice");
  }
  r.model->check_joints(q);
  return q;
}

std::vector<QueryShape> WorldModel::robot_shapes(const RobotQuery& query) const {
  const auto& r = robot(query.robot);
  r.model->check_joints(query.joints);
  std::map<std::string, double> q = r.joints;
  for (const auto& [name, value] : query.joints) q[name] = value;
  const auto T_world_links = r.model->link_poses(q, r.T_world_root);
  auto shapes = r.model->collision_shapes(q, r.T_world_root);
  // Objects it carries move with their links.
  for (const auto& o : objects_) {
    if (o.attached_to.empty()) continue;
    const auto [robot_name, link] = robot_and_link(o.attached_to);
    if (robot_name != r.name || !T_world_links.count(link)) continue;
    auto it = attached_hulls_.find(o.mesh.get());
    if (it == attached_hulls_.end()) continue;  // made by refresh() for every attached object
    QueryShape s;
    s.name = o.path;
    s.kind = QueryShape::Kind::convex_hull;
    s.points = it->second.second;
    s.T_world_shape = T_world_links.at(link) * o.T_link_object;
    shapes.push_back(std::move(s));
  }
  return shapes;
}

CollisionResult WorldModel::check_robot(const RobotQuery& query, const std::vector<AllowedPair>& allowed, const CheckOptions& options,
                                        const std::vector<QueryShape>& extra) const {
  auto shapes = robot_shapes(query);
  shapes.insert(shapes.end(), extra.begin(), extra.end());
  return collision_->check(shapes, allowed, options);
}

DistanceResult WorldModel::robot_distance(const RobotQuery& query, double max_distance_m, const std::vector<AllowedPair>& allowed,
                                          const std::vector<QueryShape>& extra) const {
  auto shapes = robot_shapes(query);
  shapes.insert(shapes.end(), extra.begin(), extra.end());
  return collision_->distance(shapes, max_distance_m, allowed);
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
  // The pose it had when edited, in the world: a recognized object's first version holds it
  // relative to the mesh it was found in, which the edit's provenance does not name.
  if (!next.metadata.contains("T_world_object")) next.metadata["T_world_object"] = to_row_major(o.T_world_object);
  next.metadata["edit"] = {{"action", action}, {"author", author}, {"at", utc_now()}};
  next.provenance = Provenance{"operator-edit", {{"action", action}, {"author", author}}, {o.version_id}};
  const ObjectId stable_id = o.object_id;
  const ObjectId id = ws_.add_version(o.version_id, next);
  apply_edit(stable_id, id);
  return id;
}

// One object changed by this world model's own edit: only it is read back (and the environment
// cut's inputs renewed), not the whole folder. Without a background re-cut, the edit must re-cut
// the environment before returning anyway, which the full refresh does.
void WorldModel::apply_edit(ObjectId object_id, ObjectId version_id) {
  if (!options_.environment_in_background) {
    refresh();
    return;
  }
  SceneChanges changes;
  const ObjectInfo info = ws_.get(version_id);
  const auto old = std::find_if(objects_.begin(), objects_.end(), [&](const SceneObject& x) { return object_id && x.object_id == object_id; });
  if (object_id) first_versions_[version_id] = object_id;
  if (info.metadata.value("status", std::string("recognized")) == "deleted") {
    if (old != objects_.end()) {
      collision_->remove(old->object_id);
      changes.removed.push_back(old->object_id);
      objects_.erase(old);
    }
  } else {
    SceneObject o = scene_object(info, {}, robots_);
    o.mesh_hash = mesh_hash(o.mesh);
    if (!o.attached_to.empty()) {
      collision_->remove(o.object_id);
      if (!attached_hulls_.count(o.mesh.get())) attached_hulls_[o.mesh.get()] = {o.mesh, convex_hull_vertices(o.mesh->vertices)};
    } else if (collision_->contains(o.object_id)) {
      collision_->set_pose(o.object_id, o.T_world_object);
    } else {
      collision_->set_body(o.object_id, o.mesh, o.T_world_object, o.margin_m);
    }
    changes.changed.push_back(o.object_id);
    if (old != objects_.end()) *old = std::move(o);
    else objects_.push_back(std::move(o));
  }
  // The environment's cut now asks for these objects: poll_environment() starts it.
  if (latest_) latest_ = make_cut(whole_signature_, objects_, robots_);
  constexpr int64_t kPerRow = 1000;
  revision_ = std::max(revision_ + 1, version_id * kPerRow);
  last_changes_ = changes;
  // Read as well: when the edit's commit is the only one since the last read.
  const auto stamp = ws_.change_stamp();
  if (stamp.own == read_.own + 1 && stamp.others == read_.others) read_ = stamp;
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
  const auto& o = object_or_throw(object_id);
  if (o.attached_to.empty()) throw Error(o.path + " is not attached");
  // It stays where it was carried to (where its link is now, when the robot is in the scene).
  return edit(object_id, "detach", author, {{"attached_to", nullptr}, {"T_link_object", nullptr}, {"T_world_object", to_row_major(o.T_world_object)}});
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
  apply_edit(0, id);
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
