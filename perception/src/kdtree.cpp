#include "artisan/perception/kdtree.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

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
// lookups. Every cell of the box has an entry (4 bytes), so the grid is made only when the box
// holds few enough cells.
class CellGrid {
 public:
  /// None when the box would hold more than `max_cells` cells.
  static std::optional<CellGrid> build(const std::vector<Eigen::Vector3f>& p, float cell, size_t max_cells) {
    // (Its indices are 32-bit; a point not finite has no cell: the tree answers for such clouds.)
    if (p.empty() || p.size() > std::numeric_limits<uint32_t>::max() || !(cell > 0)) return std::nullopt;
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
    g.points_.resize(p.size());
    g.index_.resize(p.size());
    for (size_t k = 0; k < keyed.size(); ++k) {
      ++g.start_[keyed[k].first + 1];
      g.points_[k] = p[keyed[k].second];
      g.index_[k] = keyed[k].second;
    }
    for (size_t c = 1; c < g.start_.size(); ++c) g.start_[c] += g.start_[c - 1];
    return g;
  }
  float cell() const { return cell_; }
  /// Calls `visit(index, squared distance)` for every point in the cells that a ball of `radius`
  /// about `q` reaches (the caller compares the distance), cell by cell.
  template <class Visit>
  void for_each_near(const Eigen::Vector3f& q, float radius, Visit&& visit) const {
    std::array<int, 3> first{}, last{};
    for (int a = 0; a < 3; ++a) {
      const float x = (q[a] - lo_[a]) / cell_, r = radius / cell_;
      const float from = std::floor(x - r), to = std::floor(x + r), end = static_cast<float>(n_[a] - 1);
      if (!(to >= 0 && from <= end)) return;  // beyond the box (or NaN)
      first[a] = from < 0 ? 0 : static_cast<int>(from);
      last[a] = to > end ? n_[a] - 1 : static_cast<int>(to);
    }
    for (int k = first[2]; k <= last[2]; ++k)
      for (int j = first[1]; j <= last[1]; ++j) {
        const size_t row = (static_cast<size_t>(k) * static_cast<size_t>(n_[1]) + static_cast<size_t>(j)) * static_cast<size_t>(n_[0]);
        for (uint32_t u = start_[row + static_cast<size_t>(first[0])], end = start_[row + static_cast<size_t>(last[0]) + 1]; u < end; ++u)
          visit(index_[u], (points_[u] - q).squaredNorm());
      }
  }

 private:
  size_t cell_index(const Eigen::Vector3f& x) const {
    std::array<size_t, 3> c{};
    for (int a = 0; a < 3; ++a) c[a] = static_cast<size_t>(std::min(static_cast<int>((x[a] - lo_[a]) / cell_), n_[a] - 1));
    return (c[2] * static_cast<size_t>(n_[1]) + c[1]) * static_cast<size_t>(n_[0]) + c[0];
  }
  float cell_ = 0;
  Eigen::Vector3f lo_;
  std::array<int, 3> n_{};           ///< cells along x, y, z
  std::vector<uint32_t> start_;      ///< into the sorted points, per cell and one past the last
  std::vector<Eigen::Vector3f> points_;
  std::vector<uint32_t> index_;      ///< of each sorted point in the indexed points
};
}  // namespace

struct KdTree3::Impl {
  Cloud cloud;
  Tree tree;
  std::optional<CellGrid> cells;
  Impl(std::vector<Eigen::Vector3f> p, float cell) : cloud{std::move(p)}, tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    tree.buildIndex();
    // The grid may take up to 64 cells per point and eight million more (4 bytes each: a scene of
    // one view, 40,000 points in a box 1.1 by 0.7 by 1.6 m, takes 6 million cells of 6 mm).
    if (cell > 0) cells = CellGrid::build(cloud.pts, cell, 64 * cloud.pts.size() + (size_t{1} << 23));
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
  const float worst_sq = std::nextafter(radius * radius, std::numeric_limits<float>::infinity());
  if (!impl_->cells || !(radius <= impl_->cells->cell())) return nearest_below(impl_->tree, query, worst_sq);
  std::optional<std::pair<size_t, float>> best;
  float best_sq = worst_sq;
  impl_->cells->for_each_near(query, radius, [&](uint32_t i, float d_sq) {
    if (d_sq < best_sq) best_sq = d_sq, best = std::pair<size_t, float>{i, d_sq};
  });
  return best;
}

void KdTree3::within(const Eigen::Vector3f& query, float radius, std::vector<size_t>& indices) const {
  indices.clear();
  // The grid reads (2 r / cell + 1)^2 rows of cells: up to 4 cells' radius, 2 to 3 times faster
  // than the tree on a scene's surface.
  if (impl_->cells && radius <= 4 * impl_->cells->cell()) {
    const float radius_sq = radius * radius;
    impl_->cells->for_each_near(query, radius, [&](uint32_t i, float d_sq) {
      if (d_sq < radius_sq) indices.push_back(i);
    });
    return;
  }
  IndexCollector collector{radius * radius, indices};
  impl_->tree.findNeighbors(collector, query.data(), nanoflann::SearchParams(32, 0.0f, false));
}

bool KdTree3::any_within(const Eigen::Vector3f& query, float radius, const std::function<bool(size_t)>& test) const {
  FirstPassing first{radius * radius, test};
  impl_->tree.findNeighbors(first, query.data(), nanoflann::SearchParams(32, 0.0f, false));
  return first.found;
}

const std::vector<Eigen::Vector3f>& KdTree3::points() const { return impl_->cloud.pts; }

}  // namespace artisan
