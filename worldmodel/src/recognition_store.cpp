#include "artisan/worldmodel/recognition_store.hpp"

#include "artisan/worldmodel/grid_store.hpp"

#include <array>
#include <map>

#include "artisan/core/error.hpp"
#include "artisan/core/io/blob_container.hpp"
#include "artisan/core/io/bytes.hpp"
#include "artisan/perception/recognition.hpp"

namespace artisan::worldmodel {

namespace {

using nlohmann::json;

void collect_models(const Workspace& ws, ObjectId folder, std::vector<ObjectId>& out) {
  for (const auto& o : ws.children(folder)) {
    if (o.kind == ObjectKind::kModel) out.push_back(o.id);
    if (o.kind == ObjectKind::kFolder) collect_models(ws, o.id, out);
  }
}

constexpr io::BlobMagic kSpinMagic = {'A', 'R', 'T', 'I', 'S', 'S', 'P', '\x1a'};
constexpr uint32_t kSpinVersion = 1;
// Version 2: points sampled over the model's surface (version 1 used its vertices); stacks of an
// older version are recomputed when recognising.
constexpr const char* kSpinEncoding = "artisan-spin-images/2";

// Payload: f64 resolution, i32 image width, f64 support angle, u64 n, points, normals (3 f32
// each), images (width^2 f32 each, normalised).
std::vector<uint8_t> encode_spin_images(const ModelLibraryParams& params, const PointCloud& points, const Eigen::MatrixXf& images) {
  io::ByteWriter w;
  w.put<double>(params.resolution_m);
  w.put<int32_t>(params.spin.image_width);
  w.put<double>(params.spin.support_angle_deg);
  w.put<uint64_t>(points.points.size());
  w.put_array(reinterpret_cast<const float*>(points.points.data()), points.points.size() * 3);
  w.put_array(reinterpret_cast<const float*>(points.normals.data()), points.normals.size() * 3);
  w.put_array(images.data(), static_cast<size_t>(images.size()));
  return io::seal_blob(kSpinMagic, kSpinVersion, w.bytes(), true);
}

// The stored stack, or nothing when it was made with other parameters.
bool decode_spin_images(const SqlBlob& blob, const ModelLibraryParams& params, const std::string& source, PointCloud& points,
                        Eigen::MatrixXf& images) {
  const auto raw = io::open_blob(blob, kSpinMagic, kSpinVersion, "spin-image stack", source);
  io::ByteReader r(raw, source);
  const double resolution = r.get<double>("resolution");
  const int width = r.get<int32_t>("image width");
  const double support = r.get<double>("support angle");
  if (resolution != params.resolution_m || width != params.spin.image_width || support != params.spin.support_angle_deg) return false;
  const auto n = r.get<uint64_t>("point count");
  const size_t bins = static_cast<size_t>(width) * width;
  if (n > r.remaining() / (24 + 4 * bins)) r.fail("point count", std::to_string(n) + " does not fit the payload");
  points.points.resize(n);
  points.normals.resize(n);
  images.resize(static_cast<Eigen::Index>(bins), static_cast<Eigen::Index>(n));
  r.get_array(reinterpret_cast<float*>(points.points.data()), n * 3, "points");
  r.get_array(reinterpret_cast<float*>(points.normals.data()), n * 3, "normals");
  r.get_array(images.data(), bins * n, "spin images");
  if (r.remaining() != 0) r.fail("payload", "unexpected bytes at the end");
  return true;
}

}  // namespace

NewObject make_model_object(const std::string& name, const TriangleMesh& mesh, const Provenance& provenance, json metadata) {
  const ModelLibraryParams params;
  SpinImageLibrary library(params);
  library.add_model(name, mesh);
  metadata["spin_images"] = {{"points", library.model_points(0).points.size()},
                             {"resolution_m", params.resolution_m},
                             {"image_width", params.spin.image_width},
                             {"support_angle_deg", params.spin.support_angle_deg}};
  auto object = make_mesh_object(ObjectKind::kModel, "", name, mesh, provenance, std::move(metadata));
  object.blobs.push_back({"spin_images", kSpinEncoding, encode_spin_images(params, library.model_points(0), library.model_images(0))});
  return object;
}

// Where the sensors that saw a scene mesh were, in its frame: an original mesh's own sensor; a
// merged mesh's (its grid's) meshes' sensors, each moved by its pose in the grid. None when the
// mesh has no source image (imported): recognition then has no free-space test.
std::vector<SensorView> scene_sensor_views(const Workspace& ws, ObjectId scene_id) {
  const auto prov = ws.provenance(scene_id);
  if (!prov) return {};
  if (prov->operation == "mesh") {
    const auto view = sensor_view_of_mesh(ws, scene_id);
    if (view.source.rfind("no source image", 0) == 0) return {};
    return {view.view_mesh};
  }
  if (prov->operation == "merge" || prov->operation == "grid extract") {
    for (ObjectId input : prov->inputs) {
      if (ws.get(input).kind != ObjectKind::kGrid) continue;
      std::vector<SensorView> views;
      for (const auto& e : grid_meshes(ws, input)) {
        SensorView v = e.view_mesh;
        v.origin_mesh = e.T_grid_mesh * v.origin_mesh;
        v.toward_sensor_mesh = e.T_grid_mesh.linear() * v.toward_sensor_mesh;
        views.push_back(v);
      }
      return views;
    }
  }
  return {};
}

std::vector<RecognizedObject> recognize_models(Workspace& ws, ObjectId scene_id, std::vector<ObjectId> models) {
  const auto scene = ws.get(scene_id);
  if (scene.kind != ObjectKind::kMesh) throw Error(scene.path + " is a " + to_string(scene.kind) + ", not a mesh");
  if (models.empty()) collect_models(ws, ws.root(), models);
  if (models.empty()) throw Error("the workspace holds no models (import one with: artisan import FILE --as model)");
  const ModelLibraryParams library_params;
  RecognitionParams params;
  params.views = scene_sensor_views(ws, scene_id);
  SpinImageLibrary library(library_params);
  std::vector<ObjectInfo> model_info;
  for (ObjectId m : models) {
    const auto info = ws.get(m);
    if (info.kind != ObjectKind::kModel) throw Error(info.path + " is a " + to_string(info.kind) + ", not a model");
    // The stack stored at import when it matches the library's parameters, else computed now.
    PointCloud points;
    Eigen::MatrixXf images;
    bool stored = false;
    for (const auto& b : ws.blobs(m))
      if (b.role == "spin_images" && b.encoding == kSpinEncoding) stored = decode_spin_images(b.data, library_params, info.path, points, images);
    if (stored) library.add_precomputed_model(info.name, std::move(points), std::move(images));
    else library.add_model(info.name, ws.load_mesh(m));
    model_info.push_back(info);
  }
  const auto result = recognize(ws.load_mesh(scene_id), library, params);
  const json parameters = {{"resolution_m", library_params.resolution_m},
                           {"spin_image_width", library_params.spin.image_width},
                           {"support_angle_deg", library_params.spin.support_angle_deg},
                           {"pca_variance", library_params.pca_variance},
                           {"pair_step_fraction", library_params.pair_step_fraction},
                           {"pair_max_cell_share", library_params.pair_max_cell_share},
                           {"pair_reference_stride", library_params.pair_reference_stride},
                           {"scene_point_fraction", params.scene_point_fraction},
                           {"pair_seed", params.pair_seed},
                           {"min_model_overlap", params.min_model_overlap},
                           {"min_overlap_floor", params.min_overlap_floor},
                           {"axis_hypotheses", params.axis_hypotheses},
                           {"round_part_hypotheses", params.round_part_hypotheses},
                           {"round_part_min_share", library_params.round_part_min_share},
                           {"axis_slide_steps", params.axis_slide_steps},
                           {"winner_slides", params.winner_slides},
                           {"bend_slides", params.bend_slides},
                           {"evidence_slides", params.evidence_slides},
                           {"drop_refused_planes", params.drop_refused_planes},
                           {"max_rmse_factor", params.max_rmse_factor},
                           {"sensor_views", params.views.size()},
                           {"max_free_space_fraction", params.max_free_space_fraction},
                           {"free_space_own_bin", params.free_space_own_bin},
                           {"own_bin_min_incidence_deg", params.own_bin_min_incidence_deg},
                           {"search_rounds", params.search_rounds},
                           {"max_incidence_deg", params.max_incidence_deg},
                           {"min_visible_explained", params.min_visible_explained},
                           {"max_support_planarity", params.max_support_planarity},
                           {"max_continued_fraction", params.max_continued_fraction},
                           {"max_continued_fraction_fixed", params.max_continued_fraction_fixed},
                           {"max_through_fraction", params.max_through_fraction},
                           {"no_votes_on_support", params.no_votes_on_support},
                           {"turn_steps", params.turn_steps},
                           {"refused_turns", params.refused_turns},
                           {"rivals", params.rivals},
                           {"losing_rivals_stay_open", params.losing_rivals_stay_open},
                           {"rival_margin", params.rival_margin},
                           {"max_shared_support", params.max_shared_support},
                           {"conflict_margin", params.conflict_margin},
                           {"ambiguity_margin", params.ambiguity_margin}};
  std::vector<RecognizedObject> out;
  ws.write([&] {
    std::map<std::string, int> count;
    for (const auto& inst : result.instances) {
      const auto& model = model_info[inst.model_index];
      json figures = {{"overlap", inst.overlap_fraction}, {"rmse_m", inst.rmse_m},        {"score", inst.score},
                      {"correspondences", inst.correspondences}, {"ambiguous", inst.ambiguous},
                      {"free_space", inst.free_space_fraction}, {"visible_explained", inst.visible_explained}};
      // The alternative, when ambiguous: another pose of this model, or another model on the same surface.
      const auto& alternative = model_info[inst.alternative_model_index];
      if (inst.ambiguous) figures["alternative_model"] = alternative.name;
      json metadata = {{"model", model.path}, {"model_id", model.id}, {"T_scene_model", to_row_major(inst.T_scene_model)}, {"figures", figures}};
      if (inst.ambiguous) {
        metadata["T_scene_model_alternative"] = to_row_major(inst.T_scene_model_alternative);
        metadata["alternative_model"] = alternative.path;
        metadata["alternative_model_id"] = alternative.id;
      }
      if (model.metadata.contains("T_model_grasps")) {
        json grasps = json::array();
        for (const auto& g : model.metadata["T_model_grasps"]) {
          std::array<double, 16> a{};
          for (size_t k = 0; k < 16; ++k) a[k] = g[k].get<double>();
          grasps.push_back(to_row_major(inst.T_scene_model * from_row_major(a)));
        }
        metadata["T_scene_grasps"] = grasps;
      }
      NewObject o;
      o.kind = ObjectKind::kRecognizedModel;
      o.subkind = model.name;
      o.name = model.name + "-in-" + scene.name + "-" + std::to_string(++count[model.name]);
      o.metadata = metadata;
      o.provenance = Provenance{"recognize", parameters, {scene_id, model.id}};
      // Re-running recognition makes new versions of the same instances.
      std::optional<ObjectId> existing;
      for (const auto& c : ws.children(*scene.folder))
        if (c.name == o.name && c.kind == ObjectKind::kRecognizedModel) existing = c.id;
      const ObjectId id = existing ? ws.add_version(*existing, o) : ws.add(*scene.folder, o);
      out.push_back({id, model.name, inst.T_scene_model, figures});
    }
  });
  return out;
}

}  // namespace artisan::worldmodel
