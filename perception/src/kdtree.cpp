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

// Cubic cells of one size over the points' bounding box, for queries no wider than a cell: the
// points sorted into rows of cells along the box's longest axis (a row: the points of one pair of
// cell indices on the two other axes, ordered along it), so that a query reads the few cells about
// it from at most nine rows, contiguous in memory. Only rows are indexed: a scene's box is mostly
// empty, and a row array costs the cells of one face of the box.
class CellRows {
 public:
  /// None when the rows would need more than `max_rows` entries.
  static std::optional<CellRows> build(const std::vector<Eigen::Vector3f>& p, float cell, size_t max_rows) {
    // (Its indices are 32-bit; a point not finite has no cell: the tree answers for such clouds.)
    if (p.empty() || p.size() > std::numeric_limits<uint32_t>::max() || !(cell > 0)) return std::nullopt;
    Eigen::Vector3f lo = p.front(), hi = p.front();
    for (const auto& x : p) {
      if (!x.allFinite()) return std::nullopt;
      lo = lo.cwiseMin(x), hi = hi.cwiseMax(x);
    }
    CellRows g;
    g.cell_ = cell;
    g.lo_ = lo;
    Eigen::Index along = 0;
    (hi - lo).maxCoeff(&along);
    g.axes_ = {static_cast<int>(along), static_cast<int>((along + 1) % 3), static_cast<int>((along + 2) % 3)};
    for (int a = 0; a < 3; ++a) {
      const double cells = std::floor((hi[g.axes_[a]] - lo[g.axes_[a]]) / cell) + 1;
      if (cells > static_cast<double>(std::numeric_limits<int>::max())) return std::nullopt;
      g.n_[a] = static_cast<int>(cells);
    }
    if (static_cast<double>(g.n_[1]) * g.n_[2] > static_cast<double>(max_rows)) return std::nullopt;
    std::vector<std::pair<uint64_t, uint32_t>> keyed(p.size());  // (row, cell along it), point
    for (size_t i = 0; i < p.size(); ++i) {
      const auto c = g.cell_of(p[i]);
      keyed[i] = {(static_cast<uint64_t>(g.row(c[1], c[2])) << 32) | static_cast<uint32_t>(c[0]), static_cast<uint32_t>(i)};
    }
    std::sort(keyed.begin(), keyed.end());
    g.row_start_.assign(static_cast<size_t>(g.n_[1]) * static_cast<size_t>(g.n_[2]) + 1, 0);
    g.points_.resize(p.size());
    g.index_.resize(p.size());
    g.along_.resize(p.size());
    for (size_t k = 0; k < keyed.size(); ++k) {
      ++g.row_start_[(keyed[k].first >> 32) + 1];
      g.points_[k] = p[keyed[k].second];
      g.index_[k] = keyed[k].second;
      g.along_[k] = static_cast<int>(keyed[k].first & 0xffffffffu);
    }
    for (size_t r = 1; r < g.row_start_.size(); ++r) g.row_start_[r] += g.row_start_[r - 1];
    return g;
  }
  float cell() const { return cell_; }
  /// Calls `visit(index, squared distance)` for every point in the cells that a ball of `radius`
  /// about `q` reaches (the caller compares the distance), cell by cell.
  template <class Visit>
  void for_each_near(const Eigen::Vector3f& q, float radius, Visit&& visit) const {
    std::array<int, 3> first{}, last{};
    for (int a = 0; a < 3; ++a) {
      const float x = (q[axes_[a]] - lo_[axes_[a]]) / cell_, r = radius / cell_;
      const float from = std::floor(x - r), to = std::floor(x + r), end = static_cast<float>(n_[a] - 1);
      if (!(to >= 0 && from <= end)) return;  // beyond the box (or NaN)
      first[a] = from < 0 ? 0 : static_cast<int>(from);
      last[a] = to > end ? n_[a] - 1 : static_cast<int>(to);
    }
    for (int k = first[2]; k <= last[2]; ++k)
      for (int j = first[1]; j <= last[1]; ++j) {
        const size_t r = row(j, k);
        const auto begin = along_.begin() + row_start_[r], end = along_.begin() + row_start_[r + 1];
        const auto from = std::lower_bound(begin, end, first[0]);
        const auto to = std::upper_bound(from, end, last[0]);
        for (auto u = static_cast<size_t>(from - along_.begin()); u < static_cast<size_t>(to - along_.begin()); ++u)
          visit(index_[u], (points_[u] - q).squaredNorm());
      }
  }

 private:
  std::array<int, 3> cell_of(const Eigen::Vector3f& x) const {
    std::array<int, 3> c{};
    for (int a = 0; a < 3; ++a) c[a] = std::min(static_cast<int>((x[axes_[a]] - lo_[axes_[a]]) / cell_), n_[a] - 1);
    return c;
  }
  size_t row(int j, int k) const { return static_cast<size_t>(k) * static_cast<size_t>(n_[1]) + static_cast<size_t>(j); }
  float cell_ = 0;
  Eigen::Vector3f lo_;
  std::array<int, 3> axes_{}, n_{};  ///< the axis rows run along first; cells per axis, in that order
  std::vector<uint32_t> row_start_;  ///< into the sorted points, per row and one past the last
  std::vector<Eigen::Vector3f> points_;
  std::vector<uint32_t> index_;  ///< of each sorted point in the indexed points
  std::vector<int> along_;       ///< its cell along the row
};
}  // namespace

struct KdTree3::Impl {
  Cloud cloud;
  Tree tree;
  std::optional<CellRows> cells;
  Impl(std::vector<Eigen::Vector3f> p, float cell) : cloud{std::move(p)}, tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    tree.buildIndex();
    // The rows may take up to 16 entries per point and a million more (a scene of one view at a
    // few millimetres takes a fraction of that).
    if (cell > 0) cells = CellRows::build(cloud.pts, cell, 16 * cloud.pts.size() + (size_t{1} << 20));
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
  if (impl_->cells && radius <= impl_->cells->cell()) {
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
