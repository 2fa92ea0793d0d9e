#pragma once
// Recognition over the workspace: find model objects in a mesh object and store each instance
// found as a recognized_model object (model, T_scene_model, score, evidence) with provenance.
#include <vector>

#include "artisan/worldmodel/workspace.hpp"

namespace artisan::worldmodel {

struct RecognizedObject {
  ObjectId id = 0;
  std::string model;
  Transform T_scene_model = Transform::Identity();
  nlohmann::json figures;  ///< overlap, rmse_m, score, correspondences, ambiguous (and then alternative_model: its name)
};

/// A model object: the mesh (as make_mesh_object) plus its spin-image stack at the library
/// resolution ("spin_images" data), so recognition does not recompute it.
NewObject make_model_object(const std::string& name, const TriangleMesh& mesh, const Provenance& provenance,
                            nlohmann::json metadata = nlohmann::json::object());

/// Recognizes `models` (model objects; empty: every model in the workspace) in the mesh `scene`
/// and stores the instances beside the scene mesh, in one transaction. Returns them (none when
/// no model is there).
std::vector<RecognizedObject> recognize_models(Workspace& workspace, ObjectId scene, std::vector<ObjectId> models);

}  // namespace artisan::worldmodel
