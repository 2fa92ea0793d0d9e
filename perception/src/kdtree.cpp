#include "artisan/perception/kdtree.hpp"

#include <cmath>
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
}  // namespace

struct KdTree3::Impl {
  Cloud cloud;
  Tree tree;
  explicit Impl(std::vector<Eigen::Vector3f> p) : cloud{std::move(p)}, tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    tree.buildIndex();
  }
};

KdTree3::KdTree3(std::vector<Eigen::Vector3f> points) : impl_(std::make_unique<Impl>(std::move(points))) {}
KdTree3::~KdTree3() = default;
KdTree3::KdTree3(KdTree3&&) noexcept = default;
KdTree3& KdTree3::operator=(KdTree3&&) noexcept = default;

std::pair<size_t, float> KdTree3::nearest(const Eigen::Vector3f& query) const {
  constexpr float kNone = std::numeric_limits<float>::infinity();  // a query no point is nearer than (NaN)
  return nearest_below(impl_->tree, query, kNone).value_or(std::pair<size_t, float>{0, kNone});
}

std::optional<std::pair<size_t, float>> KdTree3::nearest_within(const Eigen::Vector3f& query, float radius) const {
  // A point exactly at the radius is taken.
  return nearest_below(impl_->tree, query, std::nextafter(radius * radius, std::numeric_limits<float>::infinity()));
}

void KdTree3::within(const Eigen::Vector3f& query, float radius, std::vector<size_t>& indices) const {
  indices.clear();
  IndexCollector collector{radius * radius, indices};
  impl_->tree.findNeighbors(collector, query.data(), nanoflann::SearchParams(32, 0.0f, false));
}

const std::vector<Eigen::Vector3f>& KdTree3::points() const { return impl_->cloud.pts; }

}  // namespace artisan
