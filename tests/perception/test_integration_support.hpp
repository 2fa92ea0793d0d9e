#pragma once
// Shared by the integration tests and bench_integration: the ten bunny scans meshed and placed at
// their bun.conf poses, surface sampling and point-to-surface accuracy against a reference.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/stanford_conf.hpp"
#include "artisan/perception/integration.hpp"
#include "artisan/perception/meshing.hpp"
#include "perception/mesh_metrics.hpp"
#include "artisan/core/range_image.hpp"

namespace artisan::test {

struct PlacedScan {
  std::string name;
  TriangleMesh mesh_scan;   ///< scan frame, normals toward the scanner
  Transform T_world_scan;   ///< from bun.conf
};

/// The ten scans meshed with default MeshingParams (in parallel), in bun.conf's order of names
/// given by `names`.
inline std::vector<PlacedScan> load_placed_bunny_scans(const std::filesystem::path& bunny_dir,
                                                       const std::vector<std::string>& names) {
  const auto conf = io::read_stanford_conf(bunny_dir / "bun.conf");
  std::vector<PlacedScan> scans(names.size());
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t i = 0; i < names.size(); ++i) {
    const auto path = bunny_dir / (names[i] + ".ply");
    const auto image = io::ply_to_range_image(io::read_ply(path), path);
    scans[i].name = names[i];
    scans[i].mesh_scan = mesh_range_image(image).mesh;
    scans[i].T_world_scan = conf.scan(names[i] + ".ply").T_world_scan;
  }
  return scans;
}

/// The Cyberware scans' rays run along -z of the scan frame (see MeshingParams).
inline SensorView cyberware_view() { return SensorView::parallel(Eigen::Vector3d::UnitZ(), 1.0); }

/// Points spread evenly over a mesh's surface, each standing for `area` [m^2] of it: every
/// triangle is cut into k^2 similar triangles (k from its area and `spacing`) and their centroids kept.
struct SurfaceSamples {
  std::vector<Eigen::Vector3d> points;
  std::vector<double> area;
  double total_area = 0;
};

inline SurfaceSamples sample_surface(const TriangleMesh& mesh, double spacing) {
  SurfaceSamples out;
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                          c = mesh.vertices[f[2]].cast<double>();
    const double area = 0.5 * (b - a).cross(c - a).norm();
    if (!(area > 0)) continue;
    const int k = std::max(1, static_cast<int>(std::ceil(std::sqrt(area) / spacing)));
    const double piece = area / (k * k);
    const Eigen::Vector3d u = (b - a) / k, v = (c - a) / k;
    for (int i = 0; i < k; ++i)
      for (int j = 0; i + j < k; ++j) {
        out.points.push_back(a + (i + 1.0 / 3) * u + (j + 1.0 / 3) * v);
        out.area.push_back(piece);
        if (i + j + 1 < k) {
          out.points.push_back(a + (i + 2.0 / 3) * u + (j + 2.0 / 3) * v);
          out.area.push_back(piece);
        }
      }
    out.total_area += area;
  }
  return out;
}

/// Share of `from`'s surface area (sampled at `spacing`) within `radius` of `to`'s triangles.
inline double surface_within(const TriangleMesh& from, const TriangleMesh& to, double radius, double spacing) {
  const SurfaceSamples s = sample_surface(from, spacing);
  const TriangleDistance distance(to.vertices, to.faces, radius);
  double inside = 0, total = 0;
#pragma omp parallel for reduction(+ : inside, total)
  for (size_t i = 0; i < s.points.size(); ++i) {
    total += s.area[i];
    if (distance.distance(s.points[i]) <= radius) inside += s.area[i];
  }
  return total > 0 ? inside / total : 0.0;
}

struct MergeAccuracy {
  double accuracy_0_5mm = 0;      ///< share of the merged surface within 0.5 mm of the reference
  double completeness_1mm = 0;    ///< share of the reference within 1 mm of the merged surface
};

inline MergeAccuracy merge_accuracy(const TriangleMesh& merged, const TriangleMesh& reference) {
  MergeAccuracy a;
  a.accuracy_0_5mm = surface_within(merged, reference, 0.0005, 0.0002);
  a.completeness_1mm = surface_within(reference, merged, 0.001, 0.0002);
  return a;
}

/// Blocks on disk, so they do not count in the process's resident memory: one file in `dir`,
/// each store appended to it, an index in memory saying where every block's latest bytes are.
/// (One file per block made the file system's inode allocation, not the grid, the main cost of
/// a paged run.)
class FileBlockStore final : public BlockStore {
 public:
  explicit FileBlockStore(const std::filesystem::path& dir) : path_(dir / "blocks.pack") {
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC, 0644);
    if (fd_ < 0) throw Error("FileBlockStore: cannot open " + path_.string());
  }
  ~FileBlockStore() override { ::close(fd_); }
  FileBlockStore(const FileBlockStore&) = delete;
  FileBlockStore& operator=(const FileBlockStore&) = delete;

  std::optional<std::vector<uint8_t>> load(const BlockKey& key) override {
    const auto it = index_.find(key);
    if (it == index_.end()) return std::nullopt;
    std::vector<uint8_t> bytes(it->second.size);
    for (size_t done = 0; done < bytes.size();) {
      const ssize_t n = ::pread(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(it->second.offset + done));
      if (n <= 0) throw Error("FileBlockStore: cannot read " + path_.string());
      done += static_cast<size_t>(n);
    }
    return bytes;
  }
  void store(const BlockKey& key, const std::vector<uint8_t>& bytes) override {
    for (size_t done = 0; done < bytes.size();) {
      const ssize_t n = ::pwrite(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(end_ + done));
      if (n <= 0) throw Error("FileBlockStore: cannot write " + path_.string());
      done += static_cast<size_t>(n);
    }
    index_[key] = Extent{end_, bytes.size()};
    end_ += bytes.size();
  }
  std::vector<BlockKey> keys() override {
    std::vector<BlockKey> out;
    out.reserve(index_.size());
    for (const auto& [key, extent] : index_) out.push_back(key);
    return out;
  }

 private:
  struct Extent {
    uint64_t offset = 0;
    size_t size = 0;
  };
  std::filesystem::path path_;
  int fd_ = -1;
  uint64_t end_ = 0;
  std::map<BlockKey, Extent> index_;
};

/// The full-resolution grid mesh of a range image (two triangles per 2x2 block of valid pixels,
/// counter-clockwise seen from the sensor), without CGAL: quick inputs for paging tests.
inline TriangleMesh grid_mesh(const RangeImage& image) {
  TriangleMesh mesh;
  std::vector<int> index(image.pixel_count(), -1);
  for (size_t i = 0; i < image.pixel_count(); ++i)
    if (image.valid[i]) {
      index[i] = static_cast<int>(mesh.vertices.size());
      mesh.vertices.push_back(image.points_sensor[i]);
    }
  for (int y = 0; y + 1 < image.height; ++y)
    for (int x = 0; x + 1 < image.width; ++x) {
      const int a = index[image.index(x, y)], b = index[image.index(x + 1, y)], c = index[image.index(x, y + 1)],
                d = index[image.index(x + 1, y + 1)];
      if (a < 0 || b < 0 || c < 0 || d < 0) continue;
      // Camera frame x right, y down, z forward: (a, c, b) is counter-clockwise seen from the camera.
      mesh.faces.emplace_back(a, c, b);
      mesh.faces.emplace_back(b, c, d);
    }
  mesh.compute_vertex_normals();
  return mesh;
}

}  // namespace artisan::test
