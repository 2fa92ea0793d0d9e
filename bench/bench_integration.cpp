// Benchmark: merging the ten Stanford bunny scans (perception/integration) at their bun.conf
// poses, at voxel sizes 1, 0.5 and 0.25 mm. JSON on stdout: distribution throughput (input
// vertices/s, surface samples/s, voxel updates/s), extraction throughput (voxels/s), the block
// cache's peak and the process's peak RSS against the memory budget (blocks kept in files, so the
// store does not count; the peak is reset before each run through /proc/self/clear_refs), and
// the two acceptance figures of issue 6 measured point-to-surface against Stanford's
// bun_zipper.ply. Each voxel size runs twice: paged (blocks in files under a budget of 32, 64,
// 128 MiB, several times smaller than the grid) and in memory (no budget: the arithmetic without
// the paging); distribute_cpu_s is the process CPU time, steadier than wall time on a shared
// machine. Beside it, on the same meshed scans (vertices with their normals, in the world
// frame) and machine: PCL's Poisson surface reconstruction at depths 8 and 9, and Open3D's (Debian's
// python3-open3d, through bench/open3d_poisson.py; "not measured" when it is not installed).
#include <fcntl.h>
#include <sys/wait.h>
#include <omp.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <ctime>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <pcl/point_types.h>
#include <pcl/surface/poisson.h>
#include <pcl/PolygonMesh.h>
#include <pcl/conversions.h>

#include "artisan/core/io/mesh_io.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/perception/integration.hpp"
#include "perception/test_integration_support.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

size_t status_kib(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(field + ":", 0) == 0) return std::stoul(line.substr(field.size() + 1));
  return 0;
}

// CPU time of the whole process [s] (every thread): with other jobs on the machine, wall time
// varies from run to run, CPU time much less.
double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

void reset_peak_rss() {
  std::ofstream("/proc/self/clear_refs") << "5";
}

const std::vector<std::string> kScans = {"bun000", "bun045", "bun090", "bun180", "bun270",
                                         "bun315", "chin",   "ear_back", "top2", "top3"};

// paged: blocks in files under `budget`; otherwise every block in memory (budget unlimited), which
// measures the arithmetic of distribution without the paging.
nlohmann::json run_grid(const std::vector<artisan::test::PlacedScan>& scans, const artisan::TriangleMesh& reference,
                        double voxel, size_t budget, bool paged = true) {
  artisan::GridDefinition def;
  def.voxel_size_m = voxel;
  def.memory_budget_bytes = paged ? budget : size_t{1} << 40;
  const auto dir = std::filesystem::temp_directory_path() / ("artisan-bench-grid-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  artisan::test::FileBlockStore files(dir);
  artisan::InMemoryBlockStore memory;
  artisan::BlockStore& store = paged ? static_cast<artisan::BlockStore&>(files) : memory;
  reset_peak_rss();
  const size_t rss_before = status_kib("VmRSS");
  artisan::OccupancyGrid grid(def, store);
  size_t vertices = 0, samples = 0, updates = 0;
  double distribute_s = 0;
  const double cpu0 = cpu_seconds();
  for (size_t i = 0; i < scans.size(); ++i) {
    const auto r = grid.distribute(scans[i].mesh_scan, scans[i].T_world_scan, artisan::test::cyberware_view(),
                                   static_cast<int>(i));
    vertices += scans[i].mesh_scan.vertices.size();
    samples += r.points;
    updates += r.voxel_updates;
    distribute_s += r.seconds;
  }
  const double distribute_cpu_s = cpu_seconds() - cpu0;
  const auto t0 = Clock::now();
  grid.flush();
  const double flush_s = since(t0);
  const auto merged = grid.extract();
  const size_t peak = status_kib("VmHWM");
  const auto stats = grid.cache_stats();
  std::filesystem::remove_all(dir);
  const auto acc = artisan::test::merge_accuracy(merged.mesh, reference);
  nlohmann::json j;
  j["voxel_size_m"] = voxel;
  j["blocks"] = paged ? nullptr : nlohmann::json(memory.size());
  j["store"] = paged ? "files, paged to the budget" : "in memory, no budget";
  j["memory_budget_bytes"] = def.memory_budget_bytes;
  j["distribute_s"] = distribute_s;
  j["input_vertices"] = vertices;
  j["surface_samples"] = samples;
  j["voxel_updates"] = updates;
  j["distribute_vertices_per_s"] = vertices / distribute_s;
  j["distribute_samples_per_s"] = samples / distribute_s;
  j["distribute_cpu_s"] = distribute_cpu_s;
  j["distribute_samples_per_cpu_s"] = samples / distribute_cpu_s;
  j["distribute_voxel_updates_per_s"] = updates / distribute_s;
  j["flush_s"] = flush_s;
  j["extract_s"] = merged.seconds;
  j["extract_voxels"] = merged.voxels;
  j["extract_voxels_per_s"] = merged.voxels / merged.seconds;
  j["merged_vertices"] = merged.mesh.vertices.size();
  j["merged_faces"] = merged.mesh.faces.size();
  j["cache_peak_bytes"] = stats.peak_resident_bytes;
  j["cache_evictions"] = stats.evictions;
  j["rss_before_mib"] = rss_before / 1024.0;
  j["peak_rss_mib"] = peak / 1024.0;
  if (paged) j["peak_rss_minus_budget_mib"] = peak / 1024.0 - static_cast<double>(def.memory_budget_bytes) / 1048576.0;
  else j["peak_rss_minus_budget_mib"] = nullptr;  // no budget: every block stays in memory
  j["accuracy_within_0_5mm"] = acc.accuracy_0_5mm;
  j["completeness_within_1mm"] = acc.completeness_1mm;
  return j;
}

// The meshed scans' vertices with their normals, in the world frame: the Poisson peers' input.
std::vector<std::pair<Eigen::Vector3f, Eigen::Vector3f>> oriented_points(const std::vector<artisan::test::PlacedScan>& scans) {
  std::vector<std::pair<Eigen::Vector3f, Eigen::Vector3f>> out;
  for (const auto& s : scans) {
    auto mesh = s.mesh_scan;
    mesh.transform(s.T_world_scan);
    for (size_t i = 0; i < mesh.vertices.size(); ++i) out.emplace_back(mesh.vertices[i], mesh.normals[i]);
  }
  return out;
}

// Open3D's Poisson at `depth` on the same points, in a Python process (bench/open3d_poisson.py).
nlohmann::json run_open3d_poisson(const std::vector<artisan::test::PlacedScan>& scans, const artisan::TriangleMesh& reference,
                                  int depth) {
  const auto dir = std::filesystem::temp_directory_path() / ("artisan-bench-open3d-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto points = oriented_points(scans);
  {
    std::ofstream out(dir / "points.ply", std::ios::binary);
    out << "ply\nformat binary_little_endian 1.0\nelement vertex " << points.size()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n";
    for (const auto& [p, n] : points) {
      out.write(reinterpret_cast<const char*>(p.data()), 3 * sizeof(float));
      out.write(reinterpret_cast<const char*>(n.data()), 3 * sizeof(float));
    }
  }
  const std::string command = "/usr/bin/python3 '" + std::string(ARTISAN_BENCH_DIR) + "/open3d_poisson.py' '" + (dir / "points.ply").string() +
                              "' " + std::to_string(depth) + " '" + (dir / "mesh.ply").string() + "' > '" + (dir / "out.json").string() + "'";
  const int status = std::system(command.c_str());
  nlohmann::json j;
  j["method"] = "Open3D create_from_point_cloud_poisson depth " + std::to_string(depth) + " on the meshed scans' vertices and normals";
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    j["error"] = WIFEXITED(status) && WEXITSTATUS(status) == 3 ? "not measured: python3-open3d is not installed"
                                                                : "bench/open3d_poisson.py failed (status " + std::to_string(status) + ")";
    std::filesystem::remove_all(dir);
    return j;
  }
  const auto run = nlohmann::json::parse(std::ifstream(dir / "out.json"));
  const auto mesh = artisan::io::read_mesh(dir / "mesh.ply");
  const auto acc = artisan::test::merge_accuracy(mesh, reference);
  j["points"] = points.size();
  j["seconds"] = run["seconds"];
  j["threads"] = run["threads"];
  j["open3d_version"] = run["version"];
  j["faces"] = mesh.faces.size();
  j["accuracy_within_0_5mm"] = acc.accuracy_0_5mm;
  j["completeness_within_1mm"] = acc.completeness_1mm;
  std::filesystem::remove_all(dir);
  return j;
}

nlohmann::json run_poisson(const std::vector<artisan::test::PlacedScan>& scans, const artisan::TriangleMesh& reference,
                           int depth) {
  pcl::PointCloud<pcl::PointNormal>::Ptr cloud(new pcl::PointCloud<pcl::PointNormal>);
  for (const auto& s : scans) {
    auto mesh = s.mesh_scan;
    mesh.transform(s.T_world_scan);
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      pcl::PointNormal p;
      p.x = mesh.vertices[i].x(), p.y = mesh.vertices[i].y(), p.z = mesh.vertices[i].z();
      p.normal_x = mesh.normals[i].x(), p.normal_y = mesh.normals[i].y(), p.normal_z = mesh.normals[i].z();
      cloud->push_back(p);
    }
  }
  pcl::Poisson<pcl::PointNormal> poisson;
  poisson.setDepth(depth);
  poisson.setInputCloud(cloud);
  pcl::PolygonMesh out;
  // PCL's Poisson code prints diagnostics on stdout, which carries the JSON: silence it.
  std::fflush(stdout);
  const int saved = ::dup(1), null = ::open("/dev/null", O_WRONLY);
  ::dup2(null, 1);
  const auto t0 = Clock::now();
  poisson.reconstruct(out);
  const double seconds = since(t0);
  std::fflush(stdout);
  ::dup2(saved, 1);
  ::close(null);
  ::close(saved);
  pcl::PointCloud<pcl::PointXYZ> vertices;
  pcl::fromPCLPointCloud2(out.cloud, vertices);
  artisan::TriangleMesh mesh;
  for (const auto& p : vertices) mesh.vertices.emplace_back(p.x, p.y, p.z);
  for (const auto& poly : out.polygons)
    for (size_t k = 1; k + 1 < poly.vertices.size(); ++k)
      mesh.faces.emplace_back(poly.vertices[0], poly.vertices[k], poly.vertices[k + 1]);
  const auto acc = artisan::test::merge_accuracy(mesh, reference);
  nlohmann::json j;
  j["method"] = "pcl::Poisson depth " + std::to_string(depth) + " on the meshed scans' vertices and normals";
  j["points"] = cloud->size();
  j["seconds"] = seconds;
  j["threads"] = 1;
  j["faces"] = mesh.faces.size();
  j["accuracy_within_0_5mm"] = acc.accuracy_0_5mm;
  j["completeness_within_1mm"] = acc.completeness_1mm;
  return j;
}

}  // namespace

// --grid-only: skip the Poisson peers; --open3d-only: only Open3D's; --quick / --quick-paged: the 0.5 mm run in memory / paged only
// (tuning).
int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  const bool grid_only = mode == "--grid-only";
  const auto dir = std::filesystem::path(ARTISAN_DATA_DIR) / "stanford-bunny";
  const auto scans = artisan::test::load_placed_bunny_scans(dir, kScans);
  const auto ref_path = dir / "reconstruction" / "bun_zipper.ply";
  const auto reference = artisan::io::ply_to_mesh(artisan::io::read_ply(ref_path), ref_path);
  nlohmann::json j;
  j["threads"] = omp_get_max_threads();
  if (mode == "--quick" || mode == "--quick-paged") {  // one 0.5 mm run (tuning)
    std::printf("%s\n", run_grid(scans, reference, 0.0005, size_t{64} << 20, mode == "--quick-paged").dump(2).c_str());
    return 0;
  }
  j["scans"] = kScans;
  if (mode == "--open3d-only") {
    for (int depth : {8, 9}) j["open3d_poisson"].push_back(run_open3d_poisson(scans, reference, depth));
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  j["grid"] = nlohmann::json::array();
  j["grid"].push_back(run_grid(scans, reference, 0.001, size_t{32} << 20));
  j["grid"].push_back(run_grid(scans, reference, 0.0005, size_t{64} << 20));
  j["grid"].push_back(run_grid(scans, reference, 0.00025, size_t{128} << 20));
  j["grid_in_memory"] = nlohmann::json::array();
  for (double voxel : {0.001, 0.0005, 0.00025}) j["grid_in_memory"].push_back(run_grid(scans, reference, voxel, 0, false));
  if (grid_only) {
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  j["pcl_poisson"] = nlohmann::json::array();
  j["pcl_poisson"].push_back(run_poisson(scans, reference, 8));
  j["pcl_poisson"].push_back(run_poisson(scans, reference, 9));
  j["open3d_poisson"] = nlohmann::json::array();
  j["open3d_poisson"].push_back(run_open3d_poisson(scans, reference, 8));
  j["open3d_poisson"].push_back(run_open3d_poisson(scans, reference, 9));
  std::printf("%s\n", j.dump(2).c_str());
}
