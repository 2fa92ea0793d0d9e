// Writes the picture of the merged bunny for the docs: the ten Stanford bunny scans merged at
// their bun.conf poses in a 0.5 mm grid (perception/integration), shaded by the simulator's
// OSMesa renderer, seen from the front (+z of bun000) and a little above.
// Usage: render_merged_bunny OUT.png
#include <cstdio>
#include <utility>

#include "artisan/sim/acquisition.hpp"
#include "artisan/sim/renderer.hpp"
#include "artisan/sim/workcell.hpp"
#include "perception/test_integration_support.hpp"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s OUT.png\n", argv[0]);
    return 1;
  }
  using namespace artisan;
  const auto dir = std::filesystem::path(ARTISAN_DATA_DIR) / "stanford-bunny";
  const auto scans = test::load_placed_bunny_scans(
      dir, {"bun000", "bun045", "bun090", "bun180", "bun270", "bun315", "chin", "ear_back", "top2", "top3"});
  GridDefinition def;
  def.voxel_size_m = 0.0005;
  InMemoryBlockStore store;
  OccupancyGrid grid(def, store);
  for (size_t i = 0; i < scans.size(); ++i)
    grid.distribute(scans[i].mesh_scan, scans[i].T_world_scan, test::cyberware_view(), static_cast<int>(i));
  const auto merged = grid.extract();

  sim::Workcell cell;
  cell.name = "merged-bunny";
  sim::Body body;
  body.name = "bunny";
  body.instance_id = 1;
  body.mesh = merged.mesh;
  body.material.color = Eigen::Vector3f(0.78f, 0.72f, 0.62f);
  body.material.specular = 0.2f;
  cell.bodies.push_back(body);
  const Eigen::Vector3d centre = merged.mesh.bounds().center().cast<double>();
  sim::Light light;
  light.position_world = centre + Eigen::Vector3d(0.3, 0.5, 0.6);
  cell.lights.push_back(light);
  const Eigen::Vector3d eye = centre + Eigen::Vector3d(0.0, 0.08, 0.32);
  const Eigen::Vector3d forward = (centre - eye).normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitY()).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Transform T_world_camera = Transform::Identity();
  T_world_camera.linear().col(0) = right;
  T_world_camera.linear().col(1) = down;
  T_world_camera.linear().col(2) = forward;
  T_world_camera.translation() = eye;
  sim::Renderer renderer(cell);
  sim::RenderOptions options;
  options.near_m = 0.05;
  options.far_m = 2.0;
  options.depth = false;
  options.instances = false;
  options.background = Eigen::Vector3f(1.0f, 1.0f, 1.0f);
  const auto image = renderer.render(cell, sim::camera_from_fov(800, 800, 0.62), T_world_camera, options);
  sim::write_png(image.color, argv[1]);
  std::printf("%zu vertices, %zu faces -> %s\n", merged.mesh.vertices.size(), merged.mesh.faces.size(), argv[1]);
  return 0;
}
