#pragma once
// A 3-D k-d tree (nanoflann, compiled once in kdtree.cpp) for closest-point and support queries,
// with a grid of cells for the small-radius queries ICP and verification make by the thousand.
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace artisan {

class KdTree3 {
 public:
  /// Indexes a copy of `points`. With `cell_m` > 0, nearest-within queries of a radius up to
  /// `cell_m`, within queries up to 4 `cell_m` and any_within up to 8 read a grid of cells that
  /// size instead of the tree (two to four times faster on a scene surface; the same points found,
  /// a query in empty space answered from one bit), unless the points' box holds too many such
  /// cells (more than 64 per point and eight million).
  explicit KdTree3(std::vector<Eigen::Vector3f> points, float cell_m = 0);
  ~KdTree3();
  KdTree3(KdTree3&&) noexcept;
  KdTree3& operator=(KdTree3&&) noexcept;

  /// Index of the nearest point and its squared distance [m^2]; the tree must not be empty.
  std::pair<size_t, float> nearest(const Eigen::Vector3f& query) const;
  /// The same among the points at most `radius` [m] from `query`, or none. The search only visits
  /// cells that close: a query far from every point (an ICP outlier) costs little.
  std::optional<std::pair<size_t, float>> nearest_within(const Eigen::Vector3f& query, float radius) const;
  /// Indices of every point within `radius` [m] of `query` (cleared first), unordered.
  void within(const Eigen::Vector3f& query, float radius, std::vector<size_t>& indices) const;
  /// Whether some point within `radius` [m] of `query` satisfies `test(index)`; the search stops
  /// at the first that does.
  bool any_within(const Eigen::Vector3f& query, float radius, const std::function<bool(size_t)>& test) const;
  const std::vector<Eigen::Vector3f>& points() const;
  size_t size() const { return points().size(); }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artisan
