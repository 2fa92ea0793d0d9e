#include "artisan/worldmodel/operations.hpp"

#include <functional>
#include <map>

#include "artisan/core/error.hpp"
#include "artisan/perception/meshing.hpp"

namespace artisan::worldmodel {

namespace {

using nlohmann::json;

struct Operation {
  std::function<json()> defaults;
  /// Makes the new object (name and provenance are set by the caller).
  std::function<NewObject(Workspace&, const std::vector<ObjectId>&, const json&)> run;
};

// --- mesh: range image -> original mesh (perception/meshing) -------------------------------

json meshing_to_json(const MeshingParams& p) {
  const char* rays = p.rays == MeshingParams::Rays::kAuto ? "auto" : p.rays == MeshingParams::Rays::kPerspective ? "perspective" : "parallel";
  json roi = nullptr;
  if (p.roi_pixels) roi = {p.roi_pixels->min().x(), p.roi_pixels->min().y(), p.roi_pixels->max().x(), p.roi_pixels->max().y()};
  return {{"rays", rays},
          {"parallel_ray_direction_sensor", {p.parallel_ray_direction_sensor.x(), p.parallel_ray_direction_sensor.y(), p.parallel_ray_direction_sensor.z()}},
          {"depth_jump_ratio", p.depth_jump_ratio},
          {"min_angle_deg", p.min_angle_deg},
          {"max_edge_length_m", p.max_edge_length_m},
          {"thinning_tolerance", p.thinning_tolerance},
          {"thinning_noise_per_m2", p.thinning_noise_per_m2},
          {"roi_pixels", roi}};
}

MeshingParams meshing_from_json(const json& j) {
  MeshingParams p;
  const auto rays = j.at("rays").get<std::string>();
  if (rays == "auto") p.rays = MeshingParams::Rays::kAuto;
  else if (rays == "perspective") p.rays = MeshingParams::Rays::kPerspective;
  else if (rays == "parallel") p.rays = MeshingParams::Rays::kParallel;
  else throw Error("mesh: rays \"" + rays + "\" is not auto, perspective or parallel");
  const auto& d = j.at("parallel_ray_direction_sensor");
  if (!d.is_array() || d.size() != 3) throw Error("mesh: parallel_ray_direction_sensor must be [x, y, z]");
  p.parallel_ray_direction_sensor = Eigen::Vector3d(d[0].get<double>(), d[1].get<double>(), d[2].get<double>());
  p.depth_jump_ratio = j.at("depth_jump_ratio").get<double>();
  p.min_angle_deg = j.at("min_angle_deg").get<double>();
  p.max_edge_length_m = j.at("max_edge_length_m").get<double>();
  p.thinning_tolerance = j.at("thinning_tolerance").get<double>();
  p.thinning_noise_per_m2 = j.at("thinning_noise_per_m2").get<double>();
  const auto& roi = j.at("roi_pixels");
  if (!roi.is_null()) {
    if (!roi.is_array() || roi.size() != 4) throw Error("mesh: roi_pixels must be [x_min, y_min, x_max, y_max] or null");
    p.roi_pixels = Eigen::AlignedBox2i(Eigen::Vector2i(roi[0].get<int>(), roi[1].get<int>()), Eigen::Vector2i(roi[2].get<int>(), roi[3].get<int>()));
  }
  return p;
}

NewObject run_mesh(Workspace& ws, const std::vector<ObjectId>& inputs, const json& params) {
  if (inputs.size() != 1) throw Error("mesh takes one image, not " + std::to_string(inputs.size()) + " inputs");
  const auto image = ws.load_image(inputs[0]);
  const auto result = mesh_range_image(image, meshing_from_json(params));
  json figures = {{"valid_pixels", result.valid_pixel_count},
                  {"full_grid_faces", result.full_grid_face_count},
                  {"discontinuity_edges", result.discontinuity_edge_count},
                  {"constraint_edges", result.constraint_edge_count},
                  {"steiner_vertices", result.steiner_vertex_count},
                  {"min_angle_image_deg", result.min_angle_image_deg},
                  {"faces_below_min_angle", result.faces_below_min_angle},
                  {"seconds", result.seconds}};
  json metadata = {{"meshing", figures}};
  if (image.sensor.T_world_sensor) metadata["T_world_mesh"] = to_row_major(*image.sensor.T_world_sensor);
  return make_mesh_object(ObjectKind::kMesh, "original", "", result.mesh, {}, metadata);
}

const std::map<std::string, Operation>& registry() {
  static const std::map<std::string, Operation> ops = {
      {"mesh", {[] { return meshing_to_json(MeshingParams{}); }, run_mesh}},
  };
  return ops;
}

const Operation& find(const std::string& name) {
  const auto& ops = registry();
  const auto it = ops.find(name);
  if (it == ops.end()) {
    std::string names;
    for (const auto& [n, op] : ops) names += (names.empty() ? "" : ", ") + n;
    throw Error("no operation \"" + name + "\" (operations: " + names + ")");
  }
  return it->second;
}

}  // namespace

std::vector<std::string> operation_names() {
  std::vector<std::string> names;
  for (const auto& [n, op] : registry()) names.push_back(n);
  return names;
}

json default_parameters(const std::string& operation) { return find(operation).defaults(); }

json apply_overrides(const json& base, const json& overrides, const std::string& operation) {
  json out = base;
  for (const auto& [key, value] : overrides.items()) {
    if (!base.contains(key)) {
      std::string keys;
      for (const auto& [k, v] : base.items()) keys += (keys.empty() ? "" : ", ") + k;
      throw Error(operation + ": no parameter \"" + key + "\" (parameters: " + keys + ")");
    }
    const auto& old = base[key];
    const bool both_numbers = old.is_number() && value.is_number();
    const bool nullable = (old.is_null() && value.is_array()) || (old.is_array() && value.is_null());
    if (!both_numbers && !nullable && old.type() != value.type())
      throw Error(operation + ": parameter " + key + " = " + value.dump() + " has the wrong type (it is a " +
                  std::string(old.type_name()) + ", e.g. " + old.dump() + ")");
    out[key] = value;
  }
  return out;
}

json parse_settings(const std::vector<std::string>& settings) {
  json out = json::object();
  for (const auto& s : settings) {
    const auto eq = s.find('=');
    if (eq == std::string::npos || eq == 0) throw Error("setting \"" + s + "\" is not key=value");
    const auto key = s.substr(0, eq), text = s.substr(eq + 1);
    auto value = json::parse(text, nullptr, false);
    out[key] = value.is_discarded() ? json(text) : value;
  }
  return out;
}

ObjectId run_operation(Workspace& ws, const std::string& operation, const std::vector<ObjectId>& inputs,
                       const json& overrides, ObjectId folder, const std::string& name) {
  const auto& op = find(operation);
  const json params = apply_overrides(op.defaults(), overrides, operation);
  validate_name(name);
  auto object = op.run(ws, inputs, params);  // the heavy work, outside the write transaction
  object.name = name;
  object.provenance = Provenance{operation, params, inputs};
  return ws.add(folder, object);
}

ObjectId reprocess(Workspace& ws, ObjectId id, const json& overrides) {
  const auto info = ws.get(id);
  const auto prov = ws.provenance(id);
  if (!prov || !registry().count(prov->operation))
    throw Error(info.path + " (ID " + std::to_string(id) + ") was " + (prov ? "made by " + prov->operation : "not derived") +
                "; only objects made by an operation (" + [] {
                  std::string n;
                  for (const auto& name : operation_names()) n += (n.empty() ? "" : ", ") + name;
                  return n;
                }() + ") can be reprocessed");
  const auto& op = find(prov->operation);
  // Parameters recorded by an older build may lack newer keys: fill them from the defaults.
  const json params = apply_overrides(apply_overrides(op.defaults(), prov->parameters, prov->operation), overrides, prov->operation);
  auto object = op.run(ws, prov->inputs, params);
  object.provenance = Provenance{prov->operation, params, prov->inputs};
  return ws.add_version(id, object);
}

}  // namespace artisan::worldmodel
