#include "artisan/worldmodel/grid_store.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <set>

#include "artisan/core/error.hpp"
#include "artisan/worldmodel/multimesh.hpp"
#include "utc_time.hpp"

namespace artisan::worldmodel {

namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;


std::string where(const ObjectInfo& o) { return o.path + " (ID " + std::to_string(o.id) + ")"; }

json vec_json(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

Eigen::Vector3d vec_from_json(const json& j, const char* field) {
  if (!j.is_array() || j.size() != 3) throw Error(std::string("sensor view: ") + field + " must be [x, y, z]");
  return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()};
}

Transform transform_from_json(const json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 16) throw Error(what + ": not a row-major 4x4 array");
  std::array<double, 16> m{};
  for (size_t i = 0; i < 16; ++i) m[i] = j[i].get<double>();
  return from_row_major(m);
}

ObjectInfo grid_info(const Workspace& ws, ObjectId grid) {
  auto info = ws.get(grid);
  if (info.kind != ObjectKind::kGrid) throw Error(where(info) + " is a " + to_string(info.kind) + ", not a grid");
  if (!info.metadata.contains("definition") || !info.metadata.contains("meshes"))
    throw Error(where(info) + ": the grid's metadata lacks its definition or mesh list");
  return info;
}

ObjectInfo mesh_info(const Workspace& ws, ObjectId mesh) {
  auto info = ws.get(mesh);
  if (info.kind != ObjectKind::kMesh) throw Error(where(info) + " is a " + to_string(info.kind) + ", not a mesh");
  return info;
}

GridMeshEntry entry_from_json(const json& j) {
  GridMeshEntry e;
  e.mesh = j.at("mesh").get<ObjectId>();
  e.path = j.at("path").get<std::string>();
  e.mesh_index = j.at("mesh_index").get<int>();
  e.T_grid_mesh = transform_from_json(j.at("T_grid_mesh"), "grid mesh " + e.path + ": T_grid_mesh");
  e.view_mesh = sensor_view_from_json(j.at("view"));
  e.view_source = j.value("view_source", "");
  e.points = j.value("points", size_t{0});
  e.added_at = j.value("added_at", "");
  return e;
}

// Puts a new or next version of a merged mesh named `name` in `folder`.
ObjectId store_merged(Workspace& ws, ObjectId folder, const NewObject& object) {
  for (const auto& child : ws.children(folder)) {
    if (child.name != object.name) continue;
    if (child.kind != ObjectKind::kMesh || child.subkind != "merged")
      throw Error(where(child) + " exists and is a " + to_string(child.kind) +
                  (child.subkind.empty() ? "" : " (" + child.subkind + ")") + ", not a merged mesh; choose another name");
    return ws.add_version(child.id, object);
  }
  return ws.add(folder, object);
}

}  // namespace

// ---- the block store ----

WorkspaceBlockStore::WorkspaceBlockStore(Workspace& workspace, ObjectId grid) : workspace_(workspace), grid_(grid) {
  grid_info(workspace, grid);
}

std::optional<std::vector<uint8_t>> WorkspaceBlockStore::load(const BlockKey& key) {
  return workspace_.grid_block(grid_, {key.x, key.y, key.z});
}

void WorkspaceBlockStore::store(const BlockKey& key, const std::vector<uint8_t>& bytes) {
  workspace_.put_grid_block(grid_, {key.x, key.y, key.z}, bytes);
}

std::vector<BlockKey> WorkspaceBlockStore::keys() {
  std::vector<BlockKey> out;
  for (const auto& k : workspace_.grid_block_keys(grid_)) out.push_back(BlockKey{k[0], k[1], k[2]});
  return out;
}

// ---- JSON ----

json sensor_view_to_json(const SensorView& v) {
  if (v.rays == SensorView::Rays::kPerspective) return {{"rays", "perspective"}, {"origin_mesh", vec_json(v.origin_mesh)}};
  return {{"rays", "parallel"}, {"toward_sensor_mesh", vec_json(v.toward_sensor_mesh)}, {"parallel_range_m", v.parallel_range_m}};
}

SensorView sensor_view_from_json(const json& j) {
  const auto rays = j.at("rays").get<std::string>();
  if (rays == "perspective") return SensorView::perspective(vec_from_json(j.at("origin_mesh"), "origin_mesh"));
  if (rays == "parallel")
    return SensorView::parallel(vec_from_json(j.at("toward_sensor_mesh"), "toward_sensor_mesh"), j.at("parallel_range_m").get<double>());
  throw Error("sensor view: rays \"" + rays + "\" is neither perspective nor parallel");
}

json grid_mesh_entry_to_json(const GridMeshEntry& e) {
  return {{"mesh", e.mesh},
          {"path", e.path},
          {"mesh_index", e.mesh_index},
          {"T_grid_mesh", to_row_major(e.T_grid_mesh)},
          {"view", sensor_view_to_json(e.view_mesh)},
          {"view_source", e.view_source},
          {"points", e.points},
          {"added_at", e.added_at}};
}

// ---- the sensor view of a mesh ----
//
// An original mesh is made from one image by the "mesh" operation and lies in that image's
// sensor frame (its vertices are the range image's points_sensor), so its view follows from how
// the meshing took the rays: the recorded "rays" parameter, where "auto" means parallel for a
// sensor kind starting with "cyberware" and perspective otherwise (MeshingParams::Rays::kAuto's
// rule). The Stanford bunny scans (Cyberware 3030MS, a linear-translation scanner) thus get
// parallel rays along parallel_ray_direction_sensor (-z: toward the sensor is +z), as the
// integration tests use; the simulated Minolta Vivid and Pioneer stereo rigs, whose range images
// are in their camera frame, get perspective rays from the sensor origin (0, 0, 0). Parallel rays
// have no range: the sensor model is given 1 m, which the laser model ignores (its error does not
// grow with range). A mesh with no source image (imported, or merged) is taken as seen from the
// origin of its own frame; the grid's entry records which rule was used.
MeshSensorView sensor_view_of_mesh(const Workspace& ws, ObjectId mesh) {
  const auto info = mesh_info(ws, mesh);
  const auto prov = ws.provenance(mesh);
  if (prov && prov->operation == "mesh" && prov->inputs.size() == 1) {
    const auto image = ws.get(prov->inputs[0]);
    if (image.kind == ObjectKind::kImage) {
      const std::string sensor_kind = image.subkind;
      const std::string rays = prov->parameters.value("rays", "auto");
      const bool parallel = rays == "parallel" || (rays == "auto" && sensor_kind.rfind("cyberware", 0) == 0);
      const std::string from = "image " + image.path + " (" + (sensor_kind.empty() ? "unknown sensor" : sensor_kind) + ", meshed with rays " + rays + ")";
      if (!parallel) return {SensorView::perspective(Eigen::Vector3d::Zero()), from + ": perspective from the sensor origin"};
      Eigen::Vector3d ray(0, 0, -1);
      if (prov->parameters.contains("parallel_ray_direction_sensor"))
        ray = vec_from_json(prov->parameters["parallel_ray_direction_sensor"], "parallel_ray_direction_sensor");
      if (!(ray.allFinite() && ray.norm() > 0)) throw Error(where(info) + ": its meshing recorded a zero ray direction");
      return {SensorView::parallel(-ray.normalized(), 1.0), from + ": parallel rays"};
    }
  }
  return {SensorView::perspective(Eigen::Vector3d::Zero()), "no source image: assumed perspective from the mesh frame's origin"};
}

// ---- operations ----

ObjectId create_grid(Workspace& ws, ObjectId folder, const std::string& name, const GridDefinition& definition) {
  definition.validate();
  NewObject o;
  o.kind = ObjectKind::kGrid;
  o.name = name;
  o.metadata = {{"definition", json::parse(definition.to_json())}, {"meshes", json::array()}, {"blocks", 0}, {"block_bytes", 0}};
  o.provenance = Provenance{"grid new", json::parse(definition.to_json()), {}};
  return ws.add(folder, o);
}

GridDefinition grid_definition(const Workspace& ws, ObjectId grid) {
  const auto info = grid_info(ws, grid);
  return GridDefinition::from_json(info.metadata["definition"].dump());
}

std::vector<GridMeshEntry> grid_meshes(const Workspace& ws, ObjectId grid) {
  const auto info = grid_info(ws, grid);
  std::vector<GridMeshEntry> out;
  for (const auto& j : info.metadata["meshes"]) out.push_back(entry_from_json(j));
  return out;
}

AddToGridReport add_to_grid(Workspace& ws, ObjectId grid, ObjectId mesh, const std::optional<Transform>& T_grid_mesh) {
  // Checks before the heavy work (and again inside the transaction, against a concurrent writer).
  grid_info(ws, grid);
  const auto mesh_object = mesh_info(ws, mesh);
  Transform T = Transform::Identity();
  if (T_grid_mesh) {
    T = *T_grid_mesh;
  } else if (mesh_object.metadata.contains("T_world_mesh")) {
    T = transform_from_json(mesh_object.metadata["T_world_mesh"], where(mesh_object) + ": T_world_mesh");
  }
  if (!T.matrix().allFinite()) throw Error("T_grid_mesh of " + where(mesh_object) + " is not finite");
  const auto view = sensor_view_of_mesh(ws, mesh);
  const TriangleMesh triangles = ws.load_mesh(mesh);
  AddToGridReport report;
  ws.write([&] {
    const auto info = grid_info(ws, grid);
    const auto definition = GridDefinition::from_json(info.metadata["definition"].dump());
    json meshes = info.metadata["meshes"];
    int next_index = 0;
    for (const auto& j : meshes) {
      const auto e = entry_from_json(j);
      if (e.mesh == mesh)
        throw Error(where(mesh_object) + " is already in grid " + where(info) + " (added " + e.added_at + " as mesh " +
                    std::to_string(e.mesh_index) + "); a mesh is distributed once");
      next_index = std::max(next_index, e.mesh_index + 1);
    }
    WorkspaceBlockStore store(ws, grid);
    OccupancyGrid occupancy(definition, store);
    report.distribute = occupancy.distribute(triangles, T, view.view_mesh, next_index);
    occupancy.flush();
    report.cache = occupancy.cache_stats();
    report.entry.mesh = mesh;
    report.entry.path = mesh_object.path;
    report.entry.mesh_index = next_index;
    report.entry.T_grid_mesh = T;
    report.entry.view_mesh = view.view_mesh;
    report.entry.view_source = view.source;
    report.entry.points = report.distribute.points;
    report.entry.added_at = utc_now();
    meshes.push_back(grid_mesh_entry_to_json(report.entry));
    std::tie(report.blocks, report.block_bytes) = ws.grid_block_totals(grid);
    json metadata = info.metadata;
    metadata["meshes"] = meshes;
    metadata["blocks"] = report.blocks;
    metadata["block_bytes"] = report.block_bytes;
    ws.set_metadata(grid, metadata);
    ws.add_provenance_input(grid, mesh);
  });
  return report;
}

namespace {

const char* color_name(ExtractParams::Color c) { return c == ExtractParams::Color::kBlend ? "blend" : "best_viewed"; }

// Extracts the grid's surface and stores it as a merged mesh with `provenance` (inside the
// caller's transaction or its own).
ExtractGridReport extract_and_store(Workspace& ws, ObjectId grid, ObjectId folder, const std::string& name,
                                    const ExtractParams& params, const Provenance& provenance) {
  validate_name(name);
  const auto info = grid_info(ws, grid);
  const auto definition = GridDefinition::from_json(info.metadata["definition"].dump());
  if (info.metadata["meshes"].empty()) throw Error("grid " + where(info) + " is empty: add a mesh first (artisan grid add)");
  ExtractGridReport report;
  ws.write([&] {
    WorkspaceBlockStore store(ws, grid);
    OccupancyGrid occupancy(definition, store);
    const auto result = occupancy.extract(params);
    if (result.mesh.faces.empty())
      throw Error("grid " + where(info) + " has no surface above min_likelihood " + std::to_string(params.min_likelihood));
    const json metadata = {{"grid", grid}, {"extract_seconds", result.seconds}};
    report.merged = store_merged(ws, folder, make_mesh_object(ObjectKind::kMesh, "merged", name, result.mesh, provenance, metadata));
    report.vertices = result.mesh.vertices.size();
    report.faces = result.mesh.faces.size();
    report.blocks = result.blocks;
    report.seconds = result.seconds;
  });
  return report;
}

}  // namespace

ExtractGridReport extract_grid(Workspace& ws, ObjectId grid, ObjectId folder, const std::string& name, const ExtractParams& params) {
  std::vector<ObjectId> inputs = {grid};
  json meshes = json::array();
  for (const auto& e : grid_meshes(ws, grid)) {
    inputs.push_back(e.mesh);
    meshes.push_back({{"mesh", e.mesh}, {"path", e.path}});
  }
  const json parameters = {{"min_likelihood", params.min_likelihood}, {"color", color_name(params.color)}, {"grid", grid}, {"meshes", meshes}};
  return extract_and_store(ws, grid, folder, name, params, Provenance{"grid extract", parameters, inputs});
}

MergeReport merge_multimesh(Workspace& ws, ObjectId multimesh, const GridDefinition& definition, const ExtractParams& params,
                            const ProgressFn& progress) {
  const auto t0 = Clock::now();
  definition.validate();
  const auto mm = ws.get(multimesh);
  if (mm.kind != ObjectKind::kMultiMesh) throw Error(where(mm) + " is a " + to_string(mm.kind) + ", not a multimesh");
  const auto members = ws.members(multimesh);
  if (members.empty()) throw Error("multimesh " + where(mm) + " has no members: add meshes first (artisan multimesh add)");
  const auto T_root = root_transforms(members);
  const ObjectId folder = *mm.folder;
  MergeReport report;
  ws.write([&] {
    // The grid: a new one, or the next version of an existing grid of that name.
    NewObject grid_object;
    grid_object.kind = ObjectKind::kGrid;
    grid_object.name = mm.name + "-grid";
    grid_object.metadata = {{"definition", json::parse(definition.to_json())}, {"meshes", json::array()}, {"blocks", 0}, {"block_bytes", 0}};
    grid_object.provenance = Provenance{"grid new", json::parse(definition.to_json()), {}};
    std::optional<ObjectId> existing;
    for (const auto& child : ws.children(folder))
      if (child.name == grid_object.name) {
        if (child.kind != ObjectKind::kGrid)
          throw Error(where(child) + " exists and is a " + to_string(child.kind) + ", not a grid; rename it to merge " + mm.path);
        existing = child.id;
      }
    report.grid = existing ? ws.add_version(*existing, grid_object) : ws.add(folder, grid_object);
    json member_list = json::array();
    for (size_t i = 0; i < members.size(); ++i) {
      const auto& m = members[i];
      const Transform& T = T_root.at(m.member_id);
      auto added = add_to_grid(ws, report.grid, m.mesh, T);
      if (progress) progress(i + 1, members.size() + 1, added.entry.path + " distributed");
      member_list.push_back({{"member", m.member_id}, {"mesh", m.mesh}, {"path", added.entry.path}, {"T_root_member", to_row_major(T)}});
      report.added.push_back(std::move(added));
    }
    // The merged mesh's provenance is the merge as a whole.
    std::vector<ObjectId> inputs = {multimesh, report.grid};
    for (const auto& m : members) inputs.push_back(m.mesh);
    const json parameters = {{"definition", json::parse(definition.to_json())},
                             {"min_likelihood", params.min_likelihood},
                             {"color", color_name(params.color)},
                             {"multimesh", multimesh},
                             {"grid", report.grid},
                             {"members", member_list}};
    report.extract = extract_and_store(ws, report.grid, folder, mm.name + "-merged", params, Provenance{"merge", parameters, inputs});
    if (progress) progress(members.size() + 1, members.size() + 1, "surface extracted");
  });
  report.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return report;
}

}  // namespace artisan::worldmodel
