// Paging to a memory budget (perception/integration), in its own executable so that nothing else
// raises the process's peak resident memory. Method: 27 spheres (radius 4 cm, 12 cm apart), each
// seen by its own synthetic 320 x 240 pinhole camera, are distributed into a 1 mm grid whose
// blocks live in files (not in this process's memory) under a 12 MiB budget; the grid grows
// several times larger than the budget. The peak RSS (VmHWM) must stay within the RSS before
// the run plus the budget plus a fixed overhead (inputs, splats, allocator slack) plus twice the
// output mesh, and the extracted surface must equal the one from an unlimited in-memory grid.
#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "artisan/perception/integration.hpp"
#include "perception/synthetic_range.hpp"
#include "perception/test_integration_support.hpp"
#include "test_support.hpp"

namespace artisan {
namespace {

size_t status_kib(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(field + ":", 0) == 0) return std::stoul(line.substr(field.size() + 1));
  return 0;
}

struct View {
  TriangleMesh mesh_camera;
  Transform T_world_camera;
};

// Sphere i at (0.12 * (i % 3), 0.12 * (i / 3 % 3), 0.12 * (i / 9)), seen from 0.25 m away along -z.
View sphere_view(int i) {
  test::AnalyticScene scene;
  scene.spheres.push_back({Eigen::Vector3d(0, 0, 0.25), 0.04});
  View v;
  v.mesh_camera = test::grid_mesh(test::render_range_image(PinholeCamera{320, 240, 262.5, 262.5, 159.5, 119.5}, scene));
  v.T_world_camera = Transform::Identity();
  v.T_world_camera.translation() = Eigen::Vector3d(0.12 * (i % 3), 0.12 * (i / 3 % 3), 0.12 * (i / 9) - 0.25);
  return v;
}

TEST(IntegrationPaging, PeakMemoryStaysWithinBudgetAndSurfaceIsUnchanged) {
  constexpr int kSpheres = 27;
  GridDefinition def;
  def.voxel_size_m = 0.001;
  def.block_edge_voxels = 16;  // 12 MiB holds 8 of these (the default 32-voxel blocks need 18 MiB)
  def.memory_budget_bytes = size_t{12} << 20;
  test::TempDir dir;
  test::FileBlockStore files(dir.path());
  const size_t rss_before_kib = status_kib("VmRSS");
  ExtractResult paged;
  GridCacheStats stats;
  {
    OccupancyGrid grid(def, files);
    for (int i = 0; i < kSpheres; ++i) {
      const View v = sphere_view(i);
      grid.distribute(v.mesh_camera, v.T_world_camera, SensorView::perspective(Eigen::Vector3d::Zero()), i);
    }
    paged = grid.extract();
    stats = grid.cache_stats();
  }
  const size_t peak_kib = status_kib("VmHWM");
  // The fixed overhead, plus the extracted mesh, which extraction holds twice over
  // (the blocks' pieces and the merged mesh): it grows with the surface, not with the grid.
  const auto& m = paged.mesh;
  const size_t mesh_kib = (m.vertices.size() * sizeof(m.vertices[0]) + m.normals.size() * sizeof(m.normals[0]) +
                           m.colors.size() * sizeof(m.colors[0]) + m.faces.size() * sizeof(m.faces[0])) / 1024;
  const size_t overhead_kib = 28 * 1024 + 2 * mesh_kib;

  // The grid's full size: every block resident at once in an unlimited in-memory grid.
  InMemoryBlockStore memory;
  GridDefinition unlimited = def;
  unlimited.memory_budget_bytes = size_t{1} << 40;
  OccupancyGrid reference(unlimited, memory);
  for (int i = 0; i < kSpheres; ++i) {
    const View v = sphere_view(i);
    reference.distribute(v.mesh_camera, v.T_world_camera, SensorView::perspective(Eigen::Vector3d::Zero()), i);
  }
  const auto full = reference.extract();
  const size_t full_bytes = reference.cache_stats().resident_bytes;

  std::printf("grid %.1f MiB in memory, budget %.1f MiB; paged run: RSS before %.1f MiB, peak %.1f MiB, "
              "mesh %.1f MiB, cache peak %.1f MiB, %zu evictions\n",
              full_bytes / 1048576.0, def.memory_budget_bytes / 1048576.0, rss_before_kib / 1024.0, peak_kib / 1024.0, mesh_kib / 1024.0,
              stats.peak_resident_bytes / 1048576.0, stats.evictions);
  RecordProperty("grid_mib", std::to_string(full_bytes / 1048576.0));
  RecordProperty("peak_rss_mib", std::to_string(peak_kib / 1024.0));
  EXPECT_GT(full_bytes, 4 * def.memory_budget_bytes);
  EXPECT_LE(peak_kib, rss_before_kib + def.memory_budget_bytes / 1024 + overhead_kib);
  ASSERT_GT(full.mesh.faces.size(), 10000u);
  EXPECT_TRUE(paged.mesh == full.mesh);
}

}  // namespace
}  // namespace artisan
