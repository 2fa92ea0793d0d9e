// Benchmark: range image -> mesh (perception/meshing) on the ten Stanford bunny scans and on a
// synthetic 640 x 480 pinhole scene. JSON on stdout: per image the time (best of 3, one thread),
// triangles against the full-resolution grid mesh, coverage of the measured points within
// 0.5 mm (point-to-triangle), smallest and 5th-percentile angles in the image plane and in 3-D,
// and the share of triangles under 10 degrees in 3-D. Beside it, on the same images: PCL's
// OrganizedFastMesh at pixel steps 1 and 3; and a 640 x 480 range image from the simulated
// Pioneer stereo head (real SGBM errors) of the sample pipework cell.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <pcl/conversions.h>
#include <pcl/point_types.h>
#include <pcl/surface/organized_fast_mesh.h>

#include "artisan/core/io/ply.hpp"
#include "artisan/sim/simulator.hpp"
#include "artisan/sim/workcell.hpp"
#include "artisan/perception/meshing.hpp"
#include "perception/mesh_metrics.hpp"
#include "perception/synthetic_range.hpp"

namespace {

using artisan::MeshingParams;
using artisan::MeshingResult;
using artisan::RangeImage;

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  auto it = v.begin() + static_cast<std::ptrdiff_t>(q * (v.size() - 1));
  std::nth_element(v.begin(), it, v.end());
  return *it;
}

nlohmann::json metrics(const std::string& name, const RangeImage& image, const MeshingResult& result, double best_s) {
  const auto& mesh = result.mesh;
  std::vector<double> angles_image, angles_3d;
  size_t slivers = 0;
  for (const auto& f : mesh.faces) {
    angles_image.push_back(artisan::test::min_triangle_angle_deg(result.vertex_pixels[f[0]], result.vertex_pixels[f[1]],
                                                                 result.vertex_pixels[f[2]]));
    const double a3 = artisan::test::min_triangle_angle_deg(
        mesh.vertices[f[0]].cast<double>().eval(), mesh.vertices[f[1]].cast<double>().eval(),
        mesh.vertices[f[2]].cast<double>().eval());
    angles_3d.push_back(a3);
    slivers += a3 < 10.0;
  }
  const double radius = 0.0005;
  const artisan::test::TriangleDistance distance(mesh.vertices, mesh.faces, radius);
  size_t covered = 0, valid = 0;
  for (size_t i = 0; i < image.pixel_count(); ++i) {
    if (!image.valid[i]) continue;
    ++valid;
    covered += distance.distance(image.points_sensor[i].cast<double>()) <= radius;
  }
  const double faces = std::max<double>(1.0, static_cast<double>(mesh.faces.size()));
  return {
      {"name", name},
      {"width", image.width},
      {"height", image.height},
      {"valid_points", valid},
      {"time_ms", best_s * 1e3},
      {"triangles", mesh.faces.size()},
      {"vertices", mesh.vertices.size()},
      {"steiner_vertices", result.steiner_vertex_count},
      {"full_grid_triangles", result.full_grid_face_count},
      {"triangle_share_of_full_grid", mesh.faces.size() / std::max(1.0, double(result.full_grid_face_count))},
      {"coverage_within_0_5mm", valid ? double(covered) / valid : 0.0},
      {"resolution_mm", result.resolution_m * 1e3},
      {"discontinuity_edges", result.discontinuity_edge_count},
      {"constraint_edges", result.constraint_edge_count},
      {"min_angle_image_deg", result.min_angle_image_deg},
      {"p5_angle_image_deg", percentile(angles_image, 0.05)},
      {"faces_below_min_angle", result.faces_below_min_angle},
      {"min_angle_3d_deg", angles_3d.empty() ? 0.0 : *std::min_element(angles_3d.begin(), angles_3d.end())},
      {"p5_angle_3d_deg", percentile(angles_3d, 0.05)},
      {"sliver_share_under_10deg_3d", slivers / faces},
  };
}

nlohmann::json measure(const std::string& name, const RangeImage& image, const MeshingParams& params) {
  MeshingResult result;
  double best_s = 1e9;
  for (int run = 0; run < 3; ++run) {
    const auto t0 = std::chrono::steady_clock::now();
    result = artisan::mesh_range_image(image, params);
    best_s = std::min(best_s, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return metrics(name, image, result, best_s);
}

// PCL's OrganizedFastMesh on the same organized points (NaN where there is no data).
nlohmann::json measure_pcl(const std::string& name, const RangeImage& image, int pixel_step) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>(image.width, image.height));
  for (size_t i = 0; i < image.pixel_count(); ++i) {
    const auto& p = image.points_sensor[i];
    (*cloud)[i] = image.valid[i] ? pcl::PointXYZ(p.x(), p.y(), p.z()) : pcl::PointXYZ(NAN, NAN, NAN);
  }
  cloud->is_dense = false;
  std::vector<pcl::Vertices> polygons;
  double best_s = 1e9;
  for (int run = 0; run < 3; ++run) {
    pcl::OrganizedFastMesh<pcl::PointXYZ> ofm;
    ofm.setInputCloud(cloud);
    ofm.setTrianglePixelSize(pixel_step);
    ofm.setTriangulationType(pcl::OrganizedFastMesh<pcl::PointXYZ>::TRIANGLE_ADAPTIVE_CUT);
    polygons.clear();
    const auto t0 = std::chrono::steady_clock::now();
    ofm.reconstruct(polygons);
    best_s = std::min(best_s, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  // The output indexes the organized cloud: vertex i is pixel (i % width, i / width).
  MeshingResult result;
  std::vector<int> remap(image.pixel_count(), -1);
  for (const auto& poly : polygons) {
    if (poly.vertices.size() != 3) continue;
    Eigen::Vector3i f;
    for (int k = 0; k < 3; ++k) {
      const auto i = poly.vertices[k];
      if (remap[i] < 0) {
        remap[i] = static_cast<int>(result.mesh.vertices.size());
        result.mesh.vertices.push_back(image.points_sensor[i]);
        result.vertex_pixels.emplace_back(double(i % image.width), double(i / image.width));
      }
      f[k] = remap[i];
    }
    result.mesh.faces.push_back(f);
  }
  result.resolution_m = result.mesh.median_edge_length();
  auto j = metrics(name, image, result, best_s);
  j["method"] = "pcl::OrganizedFastMesh TRIANGLE_ADAPTIVE_CUT, pixel step " + std::to_string(pixel_step);
  for (const char* k : {"steiner_vertices", "full_grid_triangles", "triangle_share_of_full_grid", "discontinuity_edges", "constraint_edges",
                        "faces_below_min_angle", "min_angle_image_deg"})
    j.erase(k);
  return j;
}

}  // namespace

int main() {
  const MeshingParams params;
  nlohmann::json out;
  out["benchmark"] = "meshing";
  out["params"] = {{"depth_jump_ratio", params.depth_jump_ratio},
                   {"half_cell_max_inclination_deg", params.half_cell_max_inclination_deg},
                   {"min_angle_deg", params.min_angle_deg},
                   {"min_angle_3d_deg", params.min_angle_3d_deg},
                   {"max_edge_length_m", params.max_edge_length_m},
                   {"thinning_tolerance", params.thinning_tolerance}};
  const std::string dir = std::string(ARTISAN_DATA_DIR) + "/stanford-bunny/";
  for (const char* scan : {"bun000", "bun045", "bun090", "bun180", "bun270", "bun315", "chin", "ear_back", "top2", "top3"}) {
    const std::string path = dir + scan + ".ply";
    const RangeImage image = artisan::io::ply_to_range_image(artisan::io::read_ply(path), path);
    out["images"].push_back(measure(scan, image, params));
    std::fprintf(stderr, "%s\n", out["images"].back().dump().c_str());
    for (int step : {1, 3}) out["pcl_organized_fast_mesh"].push_back(measure_pcl(scan, image, step));
  }
  // A 640 x 480 pinhole view of a tilted wall, a floor, and two spheres in front.
  artisan::test::AnalyticScene scene;
  scene.planes.push_back({Eigen::Vector3d(0.1, -0.05, -1).normalized(), -2.5, nullptr});
  scene.planes.push_back({Eigen::Vector3d(0, -1, 0), -0.6, nullptr});
  scene.spheres.push_back({Eigen::Vector3d(-0.3, 0.1, 1.6), 0.25});
  scene.spheres.push_back({Eigen::Vector3d(0.45, -0.1, 2.0), 0.3});
  const RangeImage vga = artisan::test::render_range_image(artisan::test::vga_camera(), scene);
  out["images"].push_back(measure("synthetic_vga_spheres_wall_floor", vga, params));
  std::fprintf(stderr, "%s\n", out["images"].back().dump().c_str());
  for (int step : {1, 3}) out["pcl_organized_fast_mesh"].push_back(measure_pcl("synthetic_vga_spheres_wall_floor", vga, step));
  // A 640 x 480 range image from the simulated Pioneer trinocular stereo head (SGBM).
  artisan::sim::Simulator simulator(artisan::sim::load_workcell(std::string(ARTISAN_DATA_DIR) + "/workcells/pipework.json"));
  artisan::sim::ScanRequest request;
  request.sensor = "pioneer";
  const RangeImage stereo = simulator.scan(request).range;
  out["images"].push_back(measure("simulated_pioneer_stereo_640x480", stereo, params));
  std::fprintf(stderr, "%s\n", out["images"].back().dump().c_str());
  MeshingParams stereo_params = params;
  stereo_params.thinning_noise_per_m2 = 0.005;
  out["images"].push_back(measure("simulated_pioneer_stereo_640x480_noise_floor_0.005", stereo, stereo_params));
  for (int step : {1, 3}) out["pcl_organized_fast_mesh"].push_back(measure_pcl("simulated_pioneer_stereo_640x480", stereo, step));
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
