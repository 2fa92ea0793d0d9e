#include "artisan/worldmodel/robot_store.hpp"

#include <chrono>
#include <ctime>
#include <fstream>
#include <sstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_format.hpp"
#include "artisan/core/io/mesh_io.hpp"
#include "utc_time.hpp"

namespace artisan::worldmodel {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr const char* kUrdfRole = "urdf";
constexpr const char* kUrdfEncoding = "urdf-xml";
constexpr const char* kMeshRolePrefix = "mesh:";       // + the URI as the URDF writes it
constexpr const char* kMeshEncoding = "artisan-mesh/1";  // as the workspace's meshes (checked by Workspace::check())


Transform transform_from_json(const json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 16) throw Error(what + ": expected 16 numbers (a row-major 4x4)");
  std::array<double, 16> a{};
  for (size_t k = 0; k < 16; ++k) a[k] = j[k].get<double>();
  return from_row_major(a);
}

void walk(const Workspace& ws, ObjectId folder, std::vector<ObjectInfo>& out) {
  for (const auto& c : ws.children(folder)) {
    if (c.kind == ObjectKind::kRobot) out.push_back(c);
    if (c.kind == ObjectKind::kFolder) walk(ws, c.id, out);
  }
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw Error(path.string() + ": cannot read the URDF");
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

SqlBlob to_blob(const std::string& text) { return SqlBlob(text.begin(), text.end()); }

}  // namespace

std::vector<ObjectInfo> find_robots(const Workspace& ws, const std::string& folder) {
  std::vector<ObjectInfo> out;
  walk(ws, ws.folder(folder).id, out);
  return out;
}

StoredRobot load_robot(const Workspace& ws, ObjectId id) {
  StoredRobot r;
  r.info = ws.get(id);
  const std::string where = r.info.path + " (ID " + std::to_string(id) + ")";
  if (r.info.kind != ObjectKind::kRobot) throw Error(where + " is a " + to_string(r.info.kind) + ", not a robot");
  const auto urdf = ws.blob(id, kUrdfRole);
  auto model = RobotModel::parse(std::string(urdf.begin(), urdf.end()), where, [&](const std::string& uri) {
    return io::decode_mesh(ws.blob(id, kMeshRolePrefix + uri), where + " mesh '" + uri + "'");
  });
  model.set_name(r.info.name);
  const auto& md = r.info.metadata;
  if (!md.contains("T_world_root")) throw Error(where + ": no T_world_root");
  r.T_world_root = transform_from_json(md["T_world_root"], where + ": T_world_root");
  if (!r.T_world_root.matrix().allFinite()) throw Error(where + ": T_world_root is not finite");
  r.joints = model.default_joints();
  if (md.contains("joints"))
    for (const auto& [name, value] : md["joints"].items()) r.joints[name] = value.get<double>();
  model.check_joints(r.joints);
  r.model = std::make_shared<const RobotModel>(std::move(model));
  return r;
}

ObjectId set_robot(Workspace& ws, const RobotSetRequest& req) {
  if (req.author.empty()) throw Error("robot set: an edit needs an author");
  const ObjectId folder = ws.folder(req.folder).id;
  // The robot to change, if it exists.
  std::optional<ObjectInfo> previous;
  std::string name = req.name;
  std::string urdf_text;
  if (req.urdf) {
    if (!fs::exists(*req.urdf)) throw Error("robot set: no URDF at " + req.urdf->string());
    urdf_text = read_text(*req.urdf);
  }
  if (name.empty()) {
    if (req.urdf) {
      name = RobotModel::parse(urdf_text, req.urdf->string(), [](const std::string&) { return TriangleMesh{}; }).name();
    } else {
      std::vector<ObjectInfo> here;
      for (const auto& c : ws.children(folder))
        if (c.kind == ObjectKind::kRobot) here.push_back(c);
      if (here.size() != 1)
        throw Error("robot set: " + req.folder + " has " + std::to_string(here.size()) + " robots; name the one to change (or give --urdf to add one)");
      name = here.front().name;
    }
  }
  try {
    validate_name(name);
  } catch (const Error& e) {
    throw Error(std::string("robot set: ") + e.what() + " (give the robot a name with --name)");
  }
  for (const auto& c : ws.children(folder))
    if (c.name == name) {
      if (c.kind != ObjectKind::kRobot) throw Error("robot set: " + c.path + " exists and is a " + to_string(c.kind) + ", not a robot");
      previous = c;
    }
  if (!previous && !req.urdf) throw Error("robot set: " + req.folder + " has no robot '" + name + "'; give its description with --urdf");
  if (!previous && !req.T_world_root) throw Error("robot set: a new robot needs its pose (T_world_root, --pose)");
  if (req.T_world_root && !req.T_world_root->matrix().allFinite()) throw Error("robot set: the pose is not finite");

  NewObject o;
  o.kind = ObjectKind::kRobot;
  o.name = name;
  json md = previous ? previous->metadata : json::object();
  std::shared_ptr<const RobotModel> model;
  if (req.urdf) {
    // Read the description and the collision meshes it names; keep a copy of each.
    std::map<std::string, TriangleMesh> meshes;
    json mesh_list = json::array();
    auto parsed = RobotModel::parse(urdf_text, req.urdf->string(), [&](const std::string& uri) {
      auto it = meshes.find(uri);
      if (it == meshes.end()) {
        const fs::path file = RobotModel::resolve_uri(uri, *req.urdf, req.package_paths);
        it = meshes.emplace(uri, io::read_mesh(file)).first;
        mesh_list.push_back({{"uri", uri}, {"file", fs::absolute(file).lexically_normal().string()},
                             {"vertices", it->second.vertices.size()}, {"faces", it->second.faces.size()}});
      }
      return it->second;
    });
    o.subkind = parsed.name();
    parsed.set_name(name);
    o.blobs.push_back({kUrdfRole, kUrdfEncoding, to_blob(urdf_text)});
    for (const auto& [uri, mesh] : meshes) o.blobs.push_back({kMeshRolePrefix + uri, kMeshEncoding, io::encode_mesh(mesh)});
    md["urdf"] = {{"file", fs::absolute(*req.urdf).lexically_normal().string()}, {"bytes", urdf_text.size()}};
    md["meshes"] = mesh_list;
    model = std::make_shared<const RobotModel>(std::move(parsed));
  } else {
    model = load_robot(ws, previous->id).model;
    o.subkind = previous->subkind;
    for (auto& b : ws.blobs(previous->id)) o.blobs.push_back(std::move(b));
  }
  // Joint values: the previous ones where the joint still exists, then the ones given.
  std::map<std::string, double> joints = model->default_joints();
  if (previous && previous->metadata.contains("joints"))
    for (const auto& [j, v] : previous->metadata["joints"].items())
      if (joints.count(j)) joints[j] = v.get<double>();
  model->check_joints(req.joints);
  for (const auto& [j, v] : req.joints) joints[j] = v;
  const Transform T_world_root = req.T_world_root ? *req.T_world_root : transform_from_json(md.at("T_world_root"), previous->path);

  std::vector<std::string> links;
  for (const auto& [link, mesh] : model->link_meshes()) links.push_back(link);
  const std::string action = !previous ? "create" : req.urdf ? "replace-description" : "set";
  md["root_link"] = model->root_link();
  md["T_world_root"] = to_row_major(T_world_root);
  md["joint_names"] = model->joint_names();
  md["joints"] = joints;
  md["links"] = links;
  md["edit"] = {{"action", action}, {"author", req.author}, {"at", utc_now()}};
  o.metadata = md;
  json params = {{"author", req.author}, {"urdf", req.urdf ? json(fs::absolute(*req.urdf).lexically_normal().string()) : json(nullptr)},
                 {"T_world_root", req.T_world_root ? json(to_row_major(*req.T_world_root)) : json(nullptr)}, {"joints", req.joints}};
  json packages = json::array();
  for (const auto& p : req.package_paths) packages.push_back(fs::absolute(p).lexically_normal().string());
  params["package_paths"] = packages;
  o.provenance = Provenance{"robot set", params, previous ? std::vector<ObjectId>{previous->id} : std::vector<ObjectId>{}};
  return previous ? ws.add_version(previous->id, o) : ws.add(folder, o);
}

}  // namespace artisan::worldmodel
