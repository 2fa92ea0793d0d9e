#include "artisan/worldmodel/recognition_store.hpp"

#include <array>
#include <map>

#include "artisan/core/error.hpp"
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

}  // namespace

std::vector<RecognizedObject> recognize_models(Workspace& ws, ObjectId scene_id, std::vector<ObjectId> models) {
  const auto scene = ws.get(scene_id);
  if (scene.kind != ObjectKind::kMesh) throw Error(scene.path + " is a " + to_string(scene.kind) + ", not a mesh");
  if (models.empty()) collect_models(ws, ws.root(), models);
  if (models.empty()) throw Error("the workspace holds no models (import one with: artisan import FILE --as model)");
  const ModelLibraryParams library_params;
  const RecognitionParams params;
  SpinImageLibrary library(library_params);
  std::vector<ObjectInfo> model_info;
  for (ObjectId m : models) {
    const auto info = ws.get(m);
    if (info.kind != ObjectKind::kModel) throw Error(info.path + " is a " + to_string(info.kind) + ", not a model");
    library.add_model(info.name, ws.load_mesh(m));
    model_info.push_back(info);
  }
  const auto result = recognize(ws.load_mesh(scene_id), library, params);
  const json parameters = {{"resolution_m", library_params.resolution_m},
                           {"spin_image_width", library_params.spin.image_width},
                           {"support_angle_deg", library_params.spin.support_angle_deg},
                           {"pca_variance", library_params.pca_variance},
                           {"scene_point_fraction", params.scene_point_fraction},
                           {"min_model_overlap", params.min_model_overlap},
                           {"max_rmse_factor", params.max_rmse_factor}};
  std::vector<RecognizedObject> out;
  ws.write([&] {
    std::map<std::string, int> count;
    for (const auto& inst : result.instances) {
      const auto& model = model_info[inst.model_index];
      json figures = {{"overlap", inst.overlap_fraction}, {"rmse_m", inst.rmse_m},        {"score", inst.score},
                      {"correspondences", inst.correspondences}, {"ambiguous", inst.ambiguous}};
      json metadata = {{"model", model.path}, {"model_id", model.id}, {"T_scene_model", to_row_major(inst.T_scene_model)}, {"figures", figures}};
      if (inst.ambiguous) metadata["T_scene_model_alternative"] = to_row_major(inst.T_scene_model_alternative);
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
