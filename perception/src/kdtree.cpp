#include "artisan/perception/kdtree.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <nanoflann.hpp>

namespace artisan {

namespace {
struct Cloud {
  std::vector<Eigen::Vector3f> pts;
  size_t kdtree_get_point_count() const { return pts.size(); }
  float kdtree_get_pt(size_t i, size_t dim) const { return pts[i][static_cast<int>(dim)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};
using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Cloud>, Cloud, 3, size_t>;

// The nearest point nearer than sqrt(worst_sq) (nanoflann's k-NN search prunes the cells beyond
// it), or none.
std::optional<std::pair<size_t, float>> nearest_below(const Tree& tree, const Eigen::Vector3f& query, float worst_sq) {
  size_t index = 0;
  float dist_sq = 0;
  nanoflann::KNNResultSet<float, size_t> result(1);
  result.init(&index, &dist_sq);
  dist_sq = worst_sq;
  tree.findNeighbors(result, query.data(), nanoflann::SearchParams(32, 0.0f, false));
  if (result.size() == 0) return std::nullopt;
  return std::pair{index, dist_sq};
}

// The next float above `x` (std::nextafter towards infinity; for a positive finite one without the
// library call, which cost as much as a query's bookkeeping).
float next_above(float x) {
  if (x > 0 && x < std::numeric_limits<float>::max()) return std::bit_cast<float>(std::bit_cast<uint32_t>(x) + 1);
  return std::nextafter(x, std::numeric_limits<float>::infinity());
}

// nanoflann's radius result set, collecting the indices alone into the caller's vector (its own
// collects index-distance pairs into one more vector, allocated on every query).
struct IndexCollector {
  float radius_sq;
  std::vector<size_t>& indices;
  size_t size() const { return indices.size(); }
  bool full() const { return true; }
  bool addPoint(float dist_sq, size_t index) {
    if (dist_sq < radius_sq) indices.push_back(index);
    return true;
  }
  float worstDist() const { return radius_sq; }
};

// A radius result set that stops the search at the first point passing a test.
struct FirstPassing {
  float radius_sq;
  const std::function<bool(size_t)>& test;
  bool found = false;
  size_t size() const { return found ? 1 : 0; }
  bool full() const { return true; }
  bool addPoint(float dist_sq, size_t index) {
    if (dist_sq < radius_sq && test(index)) found = true;
    return !found;
  }
  float worstDist() const { return radius_sq; }
};

// Cubic cells of one size over the points' bounding box: the points sorted by cell (cells in
// order along x, then y, then z) and, per cell, where its points start. A query reads the cells
// about it as rows of consecutive cells along x, each a contiguous run of points found by two
// lookups; the points are kept as one array per coordinate so that a run is read four at a time.
// Every cell of the box has an entry (4 bytes), so the grid is made only when the box holds few
// enough cells.
class CellGrid {
 public:
  /// None when the box would hold more than `max_cells` cells.
  static std::optional<CellGrid> build(const std::vector<Eigen::Vector3f>& p, float cell, size_t max_cells) {
    // (Its indices are 32-bit signed; a point not finite has no cell: the tree answers for such clouds.)
    if (p.empty() || p.size() > static_cast<size_t>(std::numeric_limits<int>::max()) - 4 || !(cell > 0)) return std::nullopt;
    Eigen::Vector3f lo = p.front(), hi = p.front();
    for (const auto& x : p) {
      if (!x.allFinite()) return std::nullopt;
      lo = lo.cwiseMin(x), hi = hi.cwiseMax(x);
    }
    CellGrid g;
    g.cell_ = cell;
    g.lo_ = lo;
    double cells = 1;
    for (int a = 0; a < 3; ++a) {
      const double along = std::floor((hi[a] - lo[a]) / cell) + 1;
      cells *= along;
      // (Cell indices are ints along each axis and 32-bit in all.)
      if (cells > static_cast<double>(std::min<size_t>(max_cells, std::numeric_limits<int>::max()))) return std::nullopt;
      g.n_[a] = static_cast<int>(along);
    }
    std::vector<std::pair<uint32_t, uint32_t>> keyed(p.size());  // cell, point
    for (size_t i = 0; i < p.size(); ++i) keyed[i] = {static_cast<uint32_t>(g.cell_index(p[i])), static_cast<uint32_t>(i)};
    std::sort(keyed.begin(), keyed.end());
    g.start_.assign(static_cast<size_t>(cells) + 1, 0);
    for (auto& coordinate : g.xyz_) coordinate.resize(p.size() + 3);  // (padded for reads four at a time)
    g.index_.resize(p.size());
    for (size_t k = 0; k < keyed.size(); ++k) {
      ++g.start_[keyed[k].first + 1];
      for (int a = 0; a < 3; ++a) g.xyz_[static_cast<size_t>(a)][k] = p[keyed[k].second][a];
      g.index_[k] = keyed[k].second;
    }
    for (size_t c = 1; c < g.start_.size(); ++c) g.start_[c] += g.start_[c - 1];
    // Every cell within one cell of a point's (the 27 about it) is marked as near one.
    g.near_.assign(static_cast<size_t>(cells), false);
    const size_t row = static_cast<size_t>(g.n_[0]), plane = row * static_cast<size_t>(g.n_[1]);
    for (size_t k = 0; k < keyed.size(); ++k) {
      const size_t c = keyed[k].first;
      if (k > 0 && keyed[k - 1].first == c) continue;  // (sorted: a cell's points are together)
      const int x = static_cast<int>(c % row), y = static_cast<int>(c / row % static_cast<size_t>(g.n_[1])), z = static_cast<int>(c / plane);
      for (int k2 = std::max(z - 1, 0); k2 <= std::min(z + 1, g.n_[2] - 1); ++k2)
        for (int j = std::max(y - 1, 0); j <= std::min(y + 1, g.n_[1] - 1); ++j)
          for (int i = std::max(x - 1, 0); i <= std::min(x + 1, g.n_[0] - 1); ++i)
            g.near_[static_cast<size_t>(k2) * plane + static_cast<size_t>(j) * row + static_cast<size_t>(i)] = true;
    }
    return g;
  }
  float cell() const { return cell_; }

  /// The nearest point nearer than sqrt(worst_sq) to `q` among the cells a ball of `radius` about
  /// it reaches, or none; of points equally near, the first in cell order.
  std::optional<std::pair<size_t, float>> nearest(const Eigen::Vector3f& q, float radius, float worst_sq) const {
    // Four lanes each keep their nearest so far and where it is in the sorted points (the first
    // of equals: a lane's positions only grow).
    const Query4 four(q);
    Float4 lane_best = Float4{} + worst_sq;
    Int4 lane_at = Int4{} - 1;
    for_each_run(q, radius, [&](uint32_t u, uint32_t end) {
      const Int4 last = Int4{} + (static_cast<int>(end) - 1);
      for (; u < end; u += 4) {
        // (Lanes past the run's end read the next points, or the padding, and are masked off.)
        const Float4 d_sq = squared_distances(four, u);
        const Int4 here = Int4{0, 1, 2, 3} + static_cast<int>(u);
        const Int4 nearer = (d_sq < lane_best) & (here <= last);
        lane_best = std::bit_cast<Float4>((std::bit_cast<Int4>(d_sq) & nearer) | (std::bit_cast<Int4>(lane_best) & ~nearer));
        lane_at = (here & nearer) | (lane_at & ~nearer);
      }
    });
    float best = worst_sq;
    uint32_t at = kNone;
    for (int l = 0; l < 4; ++l) {
      const auto lane_u = static_cast<uint32_t>(lane_at[l]);
      if (lane_u != kNone && (lane_best[l] < best || (lane_best[l] == best && lane_u < at))) best = lane_best[l], at = lane_u;
    }
    if (at == kNone) return std::nullopt;
    return std::pair<size_t, float>{index_[at], best};
  }

  /// Whether a point within `radius` of `q` passes `test` (asked in cell order, up to the first
  /// that passes). The distance is summed as nanoflann sums it, (x^2 + y^2) + z^2, so that the
  /// answer is the tree's.
  bool any_within(const Eigen::Vector3f& q, float radius, const std::function<bool(size_t)>& test) const {
    const float radius_sq = radius * radius;
    bool found = false;
    for_each_run(q, radius, [&](uint32_t u, uint32_t end) {
      for (; u < end && !found; ++u) {
        const float dx = xyz_[0][u] - q.x(), dy = xyz_[1][u] - q.y(), dz = xyz_[2][u] - q.z();
        found = (dx * dx + dy * dy) + dz * dz < radius_sq && test(index_[u]);
      }
    });
    return found;
  }

  /// Calls `visit(index)` for every point within `radius` of `q`, in cell order.
  template <class Visit>
  void for_each_within(const Eigen::Vector3f& q, float radius, Visit&& visit) const {
    const Query4 four(q);
    const Float4 radius_sq = Float4{} + radius * radius;
    for_each_run(q, radius, [&](uint32_t u, uint32_t end) {
      for (; u < end; u += 4) {
        const Int4 inside = squared_distances(four, u) < radius_sq;
        // (Lanes past the run's end are dropped.)
        auto lanes = lane_bits(inside) & (end - u >= 4 ? 15u : (1u << (end - u)) - 1);
        for (; lanes; lanes &= lanes - 1) visit(index_[u + static_cast<uint32_t>(__builtin_ctz(lanes))]);
      }
    });
  }

 private:
  static constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
  // Four lanes (GCC's vector extension: SSE2 on x86-64, NEON on ARM).
  using Float4 = float __attribute__((vector_size(16)));
  using Int4 = int32_t __attribute__((vector_size(16)));
  struct Query4 {  ///< a query's coordinates, each in four lanes
    Float4 x, y, z;
    explicit Query4(const Eigen::Vector3f& q) : x(Float4{} + q.x()), y(Float4{} + q.y()), z(Float4{} + q.z()) {}
  };
  /// Bit l set when lane l of `m` is (a comparison's) true.
  static unsigned lane_bits(Int4 m) {
#if defined(__SSE2__)
    return static_cast<unsigned>(_mm_movemask_ps(reinterpret_cast<__m128>(m)));
#else
    return static_cast<unsigned>((m[0] & 1) | (m[1] & 2) | (m[2] & 4) | (m[3] & 8));
#endif
  }
  static Float4 load4(const float* p) {
    Float4 v;
    std::memcpy(&v, p, sizeof v);
    return v;
  }
  /// The squared distances from the query to the sorted points u to u + 3, summed as Eigen's
  /// squaredNorm() sums a Vector3f, x^2 + (y^2 + z^2): the same distances to the bit.
  Float4 squared_distances(const Query4& q, uint32_t u) const {
    const Float4 dx = load4(xyz_[0].data() + u) - q.x, dy = load4(xyz_[1].data() + u) - q.y, dz = load4(xyz_[2].data() + u) - q.z;
    return dx * dx + (dy * dy + dz * dz);
  }
  /// Calls `run(first, end)` with the sorted points of each row of cells that a ball of `radius`
  /// about `q` reaches, in cell order.
  template <class Run>
  void for_each_run(const Eigen::Vector3f& q, float radius, Run&& run) const {
    std::array<float, 3> at{};  // q in cells from the box's corner
    for (int a = 0; a < 3; ++a) at[a] = (q[a] - lo_[a]) / cell_;
    // A query in the box whose cell has no point within one cell has none within a radius up to a
    // cell: one bit read (most of an ICP's queries from a pose far off lie in empty space).
    if (radius <= cell_ && in_box(at) && !near_[cell_of(at)]) return;
    std::array<int, 3> first{}, last{};
    const float r = radius / cell_;
    for (int a = 0; a < 3; ++a) {
      const float from = std::floor(at[a] - r), to = std::floor(at[a] + r), end = static_cast<float>(n_[a] - 1);
      if (!(to >= 0 && from <= end)) return;  // beyond the box (or NaN)
      first[a] = from < 0 ? 0 : static_cast<int>(from);
      last[a] = to > end ? n_[a] - 1 : static_cast<int>(to);
    }
    for (int k = first[2]; k <= last[2]; ++k)
      for (int j = first[1]; j <= last[1]; ++j) {
        const size_t row = (static_cast<size_t>(k) * static_cast<size_t>(n_[1]) + static_cast<size_t>(j)) * static_cast<size_t>(n_[0]);
        run(start_[row + static_cast<size_t>(first[0])], start_[row + static_cast<size_t>(last[0]) + 1]);
      }
  }
  /// Whether a place in cells from the box's corner lies in the box (false for NaN).
  bool in_box(const std::array<float, 3>& at) const {
    for (int a = 0; a < 3; ++a)
      if (!(at[a] >= 0 && at[a] < static_cast<float>(n_[a]))) return false;
    return true;
  }
  /// The cell of a place in the box, in cells from its corner.
  size_t cell_of(const std::array<float, 3>& at) const {
    return (static_cast<size_t>(at[2]) * static_cast<size_t>(n_[1]) + static_cast<size_t>(at[1])) * static_cast<size_t>(n_[0]) + static_cast<size_t>(at[0]);
  }
  size_t cell_index(const Eigen::Vector3f& x) const {
    std::array<size_t, 3> c{};
    for (int a = 0; a < 3; ++a) c[a] = static_cast<size_t>(std::min(static_cast<int>((x[a] - lo_[a]) / cell_), n_[a] - 1));
    return (c[2] * static_cast<size_t>(n_[1]) + c[1]) * static_cast<size_t>(n_[0]) + c[0];
  }
  float cell_ = 0;
  Eigen::Vector3f lo_;
  std::array<int, 3> n_{};                   ///< cells along x, y, z
  std::vector<uint32_t> start_;              ///< into the sorted points, per cell and one past the last
  std::array<std::vector<float>, 3> xyz_;    ///< the sorted points' x, y and z
  std::vector<uint32_t> index_;              ///< of each sorted point in the indexed points
  std::vector<bool> near_;                   ///< per cell, whether a point lies in it or the 26 about it
};
}  // namespace

struct KdTree3::Impl {
  Cloud cloud;
  Tree tree;
  std::optional<CellGrid> cells;
  Impl(std::vector<Eigen::Vector3f> p, float cell) : cloud{std::move(p)}, tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    if (!(cell > 0)) {
      tree.buildIndex();
      return;
    }
    // The tree and the grid are built side by side. The grid may take up to 64 cells per point and
    // eight million more (4 bytes each: a scene of one view, 40,000 points in a box 1.1 by 0.7 by
    // 1.6 m, takes 6 million cells of 6 mm).
#pragma omp parallel sections
    {
#pragma omp section
      tree.buildIndex();
#pragma omp section
      cells = CellGrid::build(cloud.pts, cell, 64 * cloud.pts.size() + (size_t{1} << 23));
    }
  }
};

KdTree3::KdTree3(std::vector<Eigen::Vector3f> points, float cell_m) : impl_(std::make_unique<Impl>(std::move(points), cell_m)) {}
KdTree3::~KdTree3() = default;
KdTree3::KdTree3(KdTree3&&) noexcept = default;
KdTree3& KdTree3::operator=(KdTree3&&) noexcept = default;

std::pair<size_t, float> KdTree3::nearest(const Eigen::Vector3f& query) const {
  constexpr float kNone = std::numeric_limits<float>::infinity();  // a query no point is nearer than (NaN)
  return nearest_below(impl_->tree, query, kNone).value_or(std::pair<size_t, float>{0, kNone});
}

std::optional<std::pair<size_t, float>> KdTree3::nearest_within(const Eigen::Vector3f& query, float radius) const {
  // A point exactly at the radius is taken.
  const float worst_sq = next_above(radius * radius);
  if (!impl_->cells || !(radius <= impl_->cells->cell())) return nearest_below(impl_->tree, query, worst_sq);
  return impl_->cells->nearest(query, radius, worst_sq);
}

void KdTree3::within(const Eigen::Vector3f& query, float radius, std::vector<size_t>& indices) const {
  indices.clear();
  // The grid reads (2 r / cell + 1)^2 rows of cells: up to 4 cells' radius, 2 to 3 times faster
  // than the tree on a scene's surface.
  if (impl_->cells && radius <= 4 * impl_->cells->cell()) {
    impl_->cells->for_each_within(query, radius, [&](uint32_t i) { indices.push_back(i); });
    return;
  }
  IndexCollector collector{radius * radius, indices};
  impl_->tree.findNeighbors(collector, query.data(), nanoflann::SearchParams(32, 0.0f, false));
}

bool KdTree3::any_within(const Eigen::Vector3f& query, float radius, const std::function<bool(size_t)>& test) const {
  // The grid up to 8 cells' radius (a spin image's flat-neighbourhood test, 4.2 cells).
  if (impl_->cells && radius <= 8 * impl_->cells->cell()) return impl_->cells->any_within(query, radius, test);
  FirstPassing first{radius * radius, test};
  impl_->tree.findNeighbors(first, query.data(), nanoflann::SearchParams(32, 0.0f, false));
  return first.found;
}

const std::vector<Eigen::Vector3f>& KdTree3::points() const { return impl_->cloud.pts; }

}  // namespace artisan
