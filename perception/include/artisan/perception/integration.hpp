#pragma once
// Merging registered meshes into one surface: probabilistic occupancy-grid integration after
// Johnson & Kang, "Registration and integration of textured 3-D data" (surface synthesis).
//
// Each mesh vertex spreads evidence into a sparse voxel grid through a Gaussian whose covariance
// is the sensor error model (elongated along the viewing ray, growing with range) plus a
// point-spread function in the tangent plane (sized to at least the local vertex spacing, so
// the evidence of one scan is a continuous sheet) plus a resolution floor. Every voxel sums
//   L      = sum g                       surface likelihood,
//   grad L = sum -g C^-1 (x - p)          its analytic gradient,
//   T      = sum g n n^T, N = sum g n     normal evidence (consensus normal: T's principal
//                                         eigenvector, oriented by N),
//   colour = sum g (1, r, g, b)           per texture channel,
// with g = w exp(-(x - p)^T C^-1 (x - p) / 2) and w = cos(view angle) * vertex area /
// (2 pi sigma_t^2), so L on a surface is about the sum of the cosines of the views that saw it.
// Sums are fixed-point integers: exact, so the grid is independent of the order meshes are
// distributed in and of how blocks were paged.
//
// Extraction: the ridge of L, i.e. the zero set of f = grad L . n / L (n the consensus normal;
// dividing by L keeps the zero set and makes f linear across a Gaussian ridge),
// where L reaches ExtractParams::min_likelihood and f decreases along n, polygonized by Marching
// Cubes (Lorensen & Cline 1987) with a table generated from a face-consistent rule (no cracks),
// oriented with the normals pointing along n (toward the sensors), one vertex per grid edge.
//
// Paging: blocks live in a BlockStore; a cache bounded by GridDefinition::memory_budget_bytes
// keeps the recently used ones (LRU) and writes dirty ones back when it evicts them.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/block_store.hpp"

namespace artisan {

/// Range-dependent sensor error model. Standard deviations at range r [m]:
///   along the viewing ray:  sigma_along_m + sigma_along_per_m * r + sigma_along_per_m2 * r^2,
///   across the ray:         sigma_across_m + sigma_across_per_m * r.
struct SensorModel {
  enum class Kind { kLaser, kStereo };
  Kind kind = Kind::kLaser;
  double sigma_along_m = 0.0002;     ///< [m] along-ray sigma at zero range
  double sigma_along_per_m = 0.0;    ///< [m/m] linear growth along the ray
  double sigma_along_per_m2 = 0.0;   ///< [1/m] quadratic growth (stereo triangulation)
  double sigma_across_m = 0.0001;    ///< [m] across-ray sigma at zero range
  double sigma_across_per_m = 0.0;   ///< [m/m] across-ray growth (pixel footprint)
  /// [1] vertices seen more obliquely than this cosine (normal . viewing direction) are ignored.
  double min_view_cosine = 0.1;

  /// A laser triangulation scanner (Cyberware, Minolta Vivid): roughly constant error.
  static SensorModel laser() { return SensorModel{}; }
  /// A stereo head: depth error grows with range squared, lateral error with range.
  static SensorModel stereo() {
    SensorModel m;
    m.kind = Kind::kStereo;
    m.sigma_along_m = 0.0;
    m.sigma_along_per_m2 = 0.002;
    m.sigma_across_m = 0.0;
    m.sigma_across_per_m = 0.001;
    return m;
  }
  double sigma_along(double range_m) const {
    return sigma_along_m + sigma_along_per_m * range_m + sigma_along_per_m2 * range_m * range_m;
  }
  double sigma_across(double range_m) const { return sigma_across_m + sigma_across_per_m * range_m; }
  bool operator==(const SensorModel&) const = default;
};

/// How colour evidence is kept.
enum class ChannelMode {
  kShared,   ///< all meshes share one texture channel
  kPerMesh,  ///< texture channel = the mesh index given to distribute()
};

/// What a grid is; fixed when it is made, stored with it (to_json / from_json).
struct GridDefinition {
  double voxel_size_m = 0.0005;  ///< [m] voxel edge
  /// [m, grid frame] evidence outside is dropped; unset: unbounded.
  std::optional<Eigen::AlignedBox3d> bounds_m;
  /// [voxels] edge of a storage block (4..64). 32: a splat's box crosses fewer block faces than
  /// with 16, and distribution in memory was 23% faster (bench_integration --quick, median of
  /// six runs each); the smallest budget (8 blocks) is then 18 MB with a colour channel.
  int block_edge_voxels = 32;
  ChannelMode channels = ChannelMode::kShared;
  SensorModel sensor = SensorModel::laser();
  /// [voxels] sigma of the point-spread function in the tangent plane; each vertex uses at
  /// least 0.7 times its own spacing (square root of its share of the mesh area).
  double point_spread_sigma_voxels = 1.0;
  /// [voxels] isotropic sigma added to every vertex so the likelihood is resolved by the grid.
  double resolution_sigma_voxels = 0.75;
  /// [sigmas] each vertex's Gaussian is cut at this Mahalanobis distance. 2.25: a splat covers
  /// 0.73 times the voxels it did at 2.5, and distribution of the ten bunny scans was 1.3 times
  /// as fast at 0.5 and 0.25 mm (three alternating runs each), with accuracy and completeness
  /// within 0.1% of what 2.5 gave (bench_integration).
  double support_sigmas = 2.25;
  size_t memory_budget_bytes = size_t{256} << 20;  ///< [bytes] block cache; at least 8 blocks

  /// Bytes of one block in memory without texture channels, and per texture channel.
  size_t block_surface_bytes() const;
  size_t block_channel_bytes() const;
  /// Throws artisan::Error naming the field and the value when a field is out of range.
  void validate() const;
  /// Compact JSON text (one line) with every field; from_json validates and throws
  /// artisan::Error naming the field on malformed text.
  std::string to_json() const;
  static GridDefinition from_json(const std::string& text);
  bool operator==(const GridDefinition& o) const;
};

/// Where the sensor was, in the mesh's own frame.
struct SensorView {
  enum class Rays {
    kPerspective,  ///< rays from origin_mesh (pinhole, Vivid, stereo)
    kParallel,     ///< parallel rays (linear-translation scanners such as the Cyberware)
  };
  Rays rays = Rays::kPerspective;
  Eigen::Vector3d origin_mesh = Eigen::Vector3d::Zero();             ///< [m] kPerspective
  Eigen::Vector3d toward_sensor_mesh = Eigen::Vector3d::UnitZ();     ///< unit, kParallel: from the surface toward the sensor
  double parallel_range_m = 1.0;  ///< [m] range given to the sensor model for kParallel

  static SensorView perspective(const Eigen::Vector3d& origin_mesh) {
    SensorView v;
    v.origin_mesh = origin_mesh;
    return v;
  }
  static SensorView parallel(const Eigen::Vector3d& toward_sensor_mesh, double range_m) {
    SensorView v;
    v.rays = Rays::kParallel;
    v.toward_sensor_mesh = toward_sensor_mesh;
    v.parallel_range_m = range_m;
    return v;
  }
};

struct DistributeResult {
  /// Surface samples that spread evidence: the vertices, plus points inside faces longer than
  /// two point-spread sigmas (the centroids of a regular subdivision), minus those skipped.
  size_t points = 0;
  size_t skipped_oblique = 0;   ///< samples seen more obliquely than min_view_cosine
  size_t skipped_outside = 0;   ///< samples whose support lies outside the bounds
  size_t blocks_touched = 0;
  size_t voxel_updates = 0;     ///< voxel contributions added
  double seconds = 0.0;         ///< wall time [s]
};

struct ExtractParams {
  /// [1] smallest surface likelihood kept (about the summed view cosines of the scans that saw
  /// a point; one scan seen head-on gives ~1): a cell is polygonized when its likeliest corner
  /// reaches it (and every corner a quarter of it). Lower keeps more of what was seen only at
  /// grazing angles and more stray layers of misregistered scans. 0.35: the ten bunny scans'
  /// merge keeps at least 99.1% of its surface within 0.5 mm of bun_zipper.ply and covers
  /// 99.95-99.97% of it within 1 mm (the scans cover 99.975%) at 1, 0.5 and 0.25 mm voxels.
  double min_likelihood = 0.35;
  enum class Color {
    kBlend,       ///< weighted mean of every channel
    kBestViewed,  ///< the channel with the most evidence at that point
  };
  Color color = Color::kBlend;
};

struct ExtractResult {
  /// Grid frame: vertices [m], faces counter-clockwise seen from outside (along the normals,
  /// toward the sensors), unit normals, colours when any mesh had them.
  TriangleMesh mesh;
  size_t blocks = 0;           ///< blocks visited
  size_t voxels = 0;           ///< voxels evaluated
  size_t cells_on_surface = 0; ///< cells that produced triangles
  double seconds = 0.0;        ///< wall time [s]
};

/// Cache figures, for tests and benchmarks.
struct GridCacheStats {
  size_t resident_bytes = 0;       ///< [bytes] block data in memory now
  size_t peak_resident_bytes = 0;  ///< [bytes] most block data ever in memory
  size_t resident_blocks = 0;
  size_t loads = 0;                ///< blocks read from the store
  size_t stores = 0;               ///< blocks written to the store
  size_t evictions = 0;
};

/// A probabilistic occupancy grid whose blocks live in a BlockStore (see the file comment).
/// Not thread-safe: one caller at a time; it parallelises internally with OpenMP.
class OccupancyGrid {
 public:
  /// Validates `definition`. The store must outlive the grid; the grid assumes it holds blocks
  /// of this definition only.
  OccupancyGrid(const GridDefinition& definition, BlockStore& store);
  /// Does not write: call flush() to persist what is still dirty in the cache.
  ~OccupancyGrid();
  OccupancyGrid(const OccupancyGrid&) = delete;
  OccupancyGrid& operator=(const OccupancyGrid&) = delete;

  /// Spreads every vertex of `mesh` (normals from the mesh or, when it has none, from its
  /// faces; colours from mesh.colors or its texture) into the grid. Normals are turned toward
  /// the sensor. mesh_index picks the texture channel under ChannelMode::kPerMesh (>= 0).
  /// Throws artisan::Error on an empty mesh, a non-finite vertex or normal, mismatched
  /// attribute sizes, a bad view or a negative mesh_index.
  DistributeResult distribute(const TriangleMesh& mesh, const Transform& T_grid_mesh, const SensorView& view_mesh,
                              int mesh_index);
  /// Writes every dirty block to the store.
  void flush();
  /// The merged surface (see the file comment); pages blocks in with their neighbours as
  /// needed. Does not modify the grid. Throws artisan::Error on bad params.
  ExtractResult extract(const ExtractParams& params = {});

  const GridDefinition& definition() const;
  GridCacheStats cache_stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artisan
