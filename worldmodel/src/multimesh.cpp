#include "artisan/worldmodel/multimesh.hpp"

#include <algorithm>
#include <array>
#include <cstdio>

#include "artisan/core/error.hpp"
#include "artisan/perception/pose_graph.hpp"
#include "artisan/perception/registration.hpp"

namespace artisan::worldmodel {

namespace {

using nlohmann::json;

json quality_json(const RegistrationResult& r) {
  return {{"overlap", r.overlap_fraction},
          {"rmse_m", r.rmse_m},
          {"conditioning", r.conditioning},
          {"flatness_m", r.flatness_m},
          {"consistent_correspondences", r.consistent_correspondences},
          {"candidate_correspondences", r.candidate_correspondences},
          {"resolution_m", r.resolution_m},
          {"seconds", r.seconds_spin_images + r.seconds_matching + r.seconds_icp}};
}

std::string figures(const RegistrationResult& r) {
  char buf[200];
  std::snprintf(buf, sizeof buf, "overlap %.2f, residual %.2f mm, %zu consistent correspondences", r.overlap_fraction, r.rmse_m * 1e3,
                r.consistent_correspondences);
  return buf + (r.failure.empty() ? std::string() : " (" + r.failure + ")");
}

}  // namespace

std::map<int64_t, Transform> root_transforms(const std::vector<MultiMeshMember>& members) {
  std::map<int64_t, Transform> T_root;
  for (const auto& m : members) {
    if (m.parent_member && !T_root.count(*m.parent_member))
      throw Error("multimesh member " + std::to_string(m.member_id) + " comes before its parent " + std::to_string(*m.parent_member));
    T_root[m.member_id] = m.parent_member ? T_root.at(*m.parent_member) * m.T_parent_member : m.T_parent_member;
  }
  return T_root;
}

ObjectId create_multimesh(Workspace& ws, ObjectId folder, const std::string& name) {
  NewObject o;
  o.kind = ObjectKind::kMultiMesh;
  o.name = name;
  o.metadata = {{"matches", json::array()}};
  return ws.add(folder, o);
}

AddMemberReport add_to_multimesh(Workspace& ws, ObjectId multimesh, const AddMemberRequest& request) {
  const auto mm = ws.get(multimesh);
  if (mm.kind != ObjectKind::kMultiMesh) throw Error(mm.path + " is a " + to_string(mm.kind) + ", not a multimesh");
  const auto mesh_info = ws.get(request.mesh);
  if (mesh_info.kind != ObjectKind::kMesh) throw Error(mesh_info.path + " is a " + to_string(mesh_info.kind) + ", not a mesh");
  const std::vector<std::string> methods = {"auto", "spin", "icp", "manual"};
  if (std::find(methods.begin(), methods.end(), request.method) == methods.end())
    throw Error("method \"" + request.method + "\" is not auto, spin, icp or manual");
  auto members = ws.members(multimesh);
  for (const auto& m : members)
    if (m.mesh == request.mesh) throw Error(mesh_info.path + " is already member " + std::to_string(m.member_id) + " of " + mm.path);

  AddMemberReport report;
  report.method = members.empty() ? "root" : request.method;
  if (members.empty()) {
    report.member = ws.add_member(multimesh, {0, request.mesh, std::nullopt, Transform::Identity(), "root", json::object()});
    return report;
  }

  // The members to register against.
  std::vector<const MultiMeshMember*> candidates;
  for (const auto& m : members)
    if (!request.parent_mesh || m.mesh == *request.parent_mesh) candidates.push_back(&m);
  if (candidates.empty()) throw Error(ws.get(*request.parent_mesh).path + " is not a member of " + mm.path);
  const TriangleMesh source = ws.load_mesh(request.mesh);

  struct Match {
    const MultiMeshMember* target;
    RegistrationResult result;
  };
  std::vector<Match> matches;
  RegistrationResult best_failure;
  if (request.method == "auto" || request.method == "spin") {
    for (const auto* c : candidates) {
      auto r = register_meshes(ws.load_mesh(c->mesh), source);
      if (r.success) matches.push_back({c, r});
      else if (r.overlap_fraction >= best_failure.overlap_fraction) best_failure = r;
    }
  } else {
    if (!request.T_parent_member_init) throw Error("method " + request.method + " needs --init (the pose of the mesh in its parent)");
    if (candidates.size() != 1) throw Error("method " + request.method + " needs --parent (the member the pose is relative to)");
    const auto* parent = candidates.front();
    if (request.method == "manual" && !request.refine) {
      RegistrationResult placed;
      placed.T_target_source = *request.T_parent_member_init;
      placed.success = true;
      matches.push_back({parent, placed});
    } else {
      auto r = refine_registration(ws.load_mesh(parent->mesh), source, *request.T_parent_member_init);
      if (r.success) matches.push_back({parent, r});
      else best_failure = r;
    }
  }
  if (matches.empty()) {
    throw Error("cannot add " + mesh_info.path + " to " + mm.path + ": the match is too weak to trust: " + figures(best_failure) +
                (request.method == "auto" || request.method == "spin" ? "; place it by hand with --method manual --init POSE --parent MESH" : ""));
  }
  const auto best = std::max_element(matches.begin(), matches.end(),
                                     [](const Match& a, const Match& b) { return a.result.overlap_fraction < b.result.overlap_fraction; });
  report.parent_member = best->target->member_id;
  report.T_parent_member = best->result.T_target_source;
  report.quality = request.method == "manual" && !request.refine ? json{{"refined", false}} : quality_json(best->result);
  report.registered_members = static_cast<int>(matches.size());

  ws.write([&] {
    report.member = ws.add_member(multimesh, {0, request.mesh, report.parent_member, report.T_parent_member, request.method, report.quality});
    auto metadata = ws.get(multimesh).metadata;
    if (!metadata.contains("matches")) metadata["matches"] = json::array();
    for (const auto& m : matches)
      metadata["matches"].push_back({{"target_member", m.target->member_id}, {"source_member", report.member},
                                     {"T_target_source", to_row_major(m.result.T_target_source)},
                                     {"overlap", m.result.overlap_fraction}, {"rmse_m", m.result.rmse_m}});
    ws.set_metadata(multimesh, metadata);

    if (matches.size() < 2) return;
    // Loop closure: the new member closes a loop; adjust every pose to all pairwise matches.
    members = ws.members(multimesh);
    const auto T_root = root_transforms(members);
    std::map<int64_t, int> node;
    std::vector<Transform> initial;
    for (const auto& m : members) {
      node[m.member_id] = static_cast<int>(initial.size());
      initial.push_back(T_root.at(m.member_id));
    }
    std::vector<PoseGraphEdge> edges;
    for (const auto& e : metadata["matches"]) {
      std::array<double, 16> a{};
      for (size_t k = 0; k < 16; ++k) a[k] = e["T_target_source"][k].get<double>();
      edges.push_back({node.at(e["target_member"].get<int64_t>()), node.at(e["source_member"].get<int64_t>()), from_row_major(a),
                       std::max(0.05, e["overlap"].get<double>())});
    }
    const auto adjusted = optimize_pose_graph(initial, edges);
    for (const auto& m : members) {
      if (!m.parent_member) continue;
      const Transform T_parent_member = adjusted.T_root_node[node.at(*m.parent_member)].inverse() * adjusted.T_root_node[node.at(m.member_id)];
      ws.set_member_transform(m.member_id, T_parent_member);
      if (m.member_id == report.member) report.T_parent_member = T_parent_member;
    }
    report.loop_closure = {{"edges", edges.size()},
                           {"rms_rotation_deg_before", adjusted.rms_rotation_deg_before},
                           {"rms_rotation_deg_after", adjusted.rms_rotation_deg_after},
                           {"rms_translation_m_before", adjusted.rms_translation_m_before},
                           {"rms_translation_m_after", adjusted.rms_translation_m_after}};
  });
  return report;
}

}  // namespace artisan::worldmodel
