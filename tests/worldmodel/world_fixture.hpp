#pragma once
// A small workcell in a workspace, for the world-model tests: a merged environment mesh (a 1 m
// floor with the Stanford bunny standing on it), the bunny as a model with one grasp frame, and
// the bunny recognized where it stands (pose known exactly).
#include <filesystem>

#include "artisan/core/io/mesh_io.hpp"
#include "artisan/worldmodel/workspace.hpp"
#include "test_support.hpp"

namespace artisan::test {

struct WorldFixture {
  worldmodel::ObjectId environment = 0, model = 0, bunny = 0;
  Transform T_world_bunny = Transform::Identity();
  Transform T_model_grasp = Transform::Identity();
  size_t floor_triangles = 0;
  TriangleMesh bunny_mesh;
};

/// A floor of `n`×`n` cells over [-0.5, 0.5]² m at z = 0, facing +z.
inline TriangleMesh floor_mesh(int n) {
  TriangleMesh m;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.vertices.emplace_back(-0.5f + float(i) / float(n), -0.5f + float(j) / float(n), 0.0f);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      m.faces.emplace_back(a, a + 1, a + n + 2);
      m.faces.emplace_back(a, a + n + 2, a + n + 1);
    }
  m.compute_vertex_normals();
  return m;
}

/// A closed box of `size` [m] centred at the origin: 12 triangles, counter-clockwise from outside.
inline TriangleMesh box_mesh(const Eigen::Vector3f& size) {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i)
    m.vertices.emplace_back((i & 1 ? 0.5f : -0.5f) * size.x(), (i & 2 ? 0.5f : -0.5f) * size.y(), (i & 4 ? 0.5f : -0.5f) * size.z());
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.faces.emplace_back(q[0], q[1], q[2]);
    m.faces.emplace_back(q[0], q[2], q[3]);
  }
  m.compute_vertex_normals();
  return m;
}

/// The UR5 of example-robot-data (data/robots); its package path is data/robots.
inline std::filesystem::path ur5_urdf() { return data_dir() / "robots/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"; }
inline std::filesystem::path robot_packages() { return data_dir() / "robots"; }

/// The bunny recognized in the merged environment (whose frame is the world's) at `T_scene_model`,
/// as the recognizer stores it.
inline worldmodel::NewObject recognized_bunny(const WorldFixture& f, const std::string& name, const Transform& T_scene_model, nlohmann::json figures) {
  worldmodel::NewObject r;
  r.kind = worldmodel::ObjectKind::kRecognizedModel;
  r.subkind = "bunny";
  r.name = name;
  r.metadata = {{"model", "/bunny"}, {"model_id", f.model}, {"T_scene_model", to_row_major(T_scene_model)}, {"figures", std::move(figures)}};
  r.provenance = worldmodel::Provenance{"recognize", {}, {f.environment, f.model}};
  return r;
}

/// Fills folder "/cell" of `ws`.
inline WorldFixture make_world_fixture(worldmodel::Workspace& ws) {
  using namespace worldmodel;
  WorldFixture f;
  f.bunny_mesh = io::read_mesh(bunny_dir() / "reconstruction" / "bun_zipper.ply");
  const float base = f.bunny_mesh.bounds().min().y();  // the bunny stands on its y-min side
  f.T_world_bunny = Transform(Eigen::Translation3d(0.1, -0.05, 0)) * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()) *
                    Eigen::Translation3d(0, -base, 0);
  f.T_model_grasp = Transform(Eigen::Translation3d(-0.02, 0.15, 0.0)) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX());
  TriangleMesh environment = floor_mesh(100);
  f.floor_triangles = environment.faces.size();
  TriangleMesh placed = f.bunny_mesh;
  placed.transform(f.T_world_bunny);
  environment.append(placed);
  const auto cell = ws.mkdir("/cell");
  f.environment = ws.add(cell, make_mesh_object(ObjectKind::kMesh, "merged", "merged", environment, {"merge", {}, {}}));
  nlohmann::json grasps = nlohmann::json::array({to_row_major(f.T_model_grasp)});
  f.model = ws.add(ws.root(), make_mesh_object(ObjectKind::kModel, "", "bunny", f.bunny_mesh, {"import", {}, {}}, {{"T_model_grasps", grasps}}));
  f.bunny = ws.add(cell, recognized_bunny(f, "bunny-in-merged-1", f.T_world_bunny,
                                          {{"score", 0.9}, {"overlap", 0.6}, {"rmse_m", 0.0004}, {"ambiguous", false}}));
  return f;
}

/// A second recognition of the bunny in /cell, `offset` [m] from the first (0.3 m along x unless
/// said), reported ambiguous with `alternative_model` at `T_world_alternative` (as the recognizer
/// stores one); its ID.
inline worldmodel::ObjectId add_ambiguous_bunny(worldmodel::Workspace& ws, const WorldFixture& f, const std::string& alternative_model,
                                                const Transform& T_world_alternative, const Eigen::Vector3d& offset = {0.3, 0, 0}) {
  auto r = recognized_bunny(f, "bunny-in-merged-2", Transform(Eigen::Translation3d(offset)) * f.T_world_bunny,
                            {{"score", 0.5}, {"overlap", 0.3}, {"rmse_m", 0.0005}, {"ambiguous", true}, {"alternative_model", alternative_model}});
  r.metadata["T_scene_model_alternative"] = to_row_major(T_world_alternative);
  return ws.add(ws.resolve("/cell").id, r);
}

}  // namespace artisan::test
