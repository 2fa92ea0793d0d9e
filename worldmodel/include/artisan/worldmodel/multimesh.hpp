#pragma once
// MultiMesh assembly: meshes added one by one, each registered to the tree (spin images then
// ICP, ICP from a given pose, or placed by hand), with loop closure by pose-graph adjustment
// when a new member overlaps several.
#include <map>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "artisan/worldmodel/workspace.hpp"

namespace artisan::worldmodel {

struct AddMemberRequest {
  ObjectId mesh = 0;
  std::optional<ObjectId> parent_mesh;     ///< register against this member's mesh only
  std::string method = "auto";             ///< auto | spin | icp | manual
  std::optional<Transform> T_parent_member_init;  ///< icp and manual: the starting pose
  bool refine = true;                      ///< manual: refine with ICP
};

struct AddMemberReport {
  int64_t member = 0;
  std::optional<int64_t> parent_member;    ///< none for the root
  Transform T_parent_member = Transform::Identity();
  std::string method;
  nlohmann::json quality = nlohmann::json::object();  ///< overlap, rmse_m, correspondences, ...
  int registered_members = 0;              ///< existing members it registered with
  nlohmann::json loop_closure = nullptr;   ///< residuals before/after the adjustment, when run
};

ObjectId create_multimesh(Workspace& workspace, ObjectId folder, const std::string& name);

/// Adds a mesh to a multimesh (the first becomes the root). Throws artisan::Error with the
/// figures when the match is too weak to trust; nothing is stored then.
AddMemberReport add_to_multimesh(Workspace& workspace, ObjectId multimesh, const AddMemberRequest& request);

/// T_root_member of every member (members are stored parents first).
std::map<int64_t, Transform> root_transforms(const std::vector<MultiMeshMember>& members);

}  // namespace artisan::worldmodel
