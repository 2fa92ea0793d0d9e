// The k-d tree's closest-point queries against brute force on random points: the nearest point,
// the nearest within a radius (a point exactly at the radius counts; none when every point is
// farther), and every point within a radius.
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <random>

#include "artisan/perception/kdtree.hpp"

namespace artisan {
namespace {

std::vector<Eigen::Vector3f> random_points(size_t n, std::mt19937& rng) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<Eigen::Vector3f> p(n);
  for (auto& x : p) x = {u(rng), u(rng), u(rng)};
  return p;
}

// Index and squared distance of the nearest of `points` to `q` by brute force.
std::pair<size_t, float> brute_nearest(const std::vector<Eigen::Vector3f>& points, const Eigen::Vector3f& q) {
  std::pair<size_t, float> best{0, std::numeric_limits<float>::infinity()};
  for (size_t i = 0; i < points.size(); ++i)
    if (const float d2 = (points[i] - q).squaredNorm(); d2 < best.second) best = {i, d2};
  return best;
}

TEST(KdTree3, NearestAndNearestWithinAgreeWithBruteForce) {
  std::mt19937 rng(7);
  const auto points = random_points(5000, rng);
  const KdTree3 tree(points);
  ASSERT_EQ(tree.size(), points.size());
  size_t within_found = 0, within_none = 0;
  for (const auto& q : random_points(2000, rng)) {
    const Eigen::Vector3f query = 1.3f * q;  // some queries outside the cloud
    const auto truth = brute_nearest(points, query);
    const auto [i, d2] = tree.nearest(query);
    EXPECT_FLOAT_EQ(d2, truth.second);
    EXPECT_FLOAT_EQ((points[i] - query).squaredNorm(), truth.second);
    const float radius = 0.06f;
    const auto near = tree.nearest_within(query, radius);
    if (truth.second <= radius * radius) {
      ASSERT_TRUE(near.has_value()) << "a point at " << std::sqrt(truth.second) << " within " << radius;
      EXPECT_FLOAT_EQ(near->second, truth.second);
      ++within_found;
    } else {
      EXPECT_FALSE(near.has_value()) << "the nearest point is " << std::sqrt(truth.second) << " away, beyond " << radius;
      ++within_none;
    }
  }
  // Both outcomes were exercised.
  EXPECT_GT(within_found, 200u);
  EXPECT_GT(within_none, 200u);
}

TEST(KdTree3, NearestWithinTakesAPointExactlyAtTheRadius) {
  const KdTree3 tree({{0, 0, 0}, {1, 0, 0}});
  const auto at = tree.nearest_within({0.25f, 0, 0}, 0.25f);
  ASSERT_TRUE(at.has_value());
  EXPECT_EQ(at->first, 0u);
  EXPECT_FLOAT_EQ(at->second, 0.0625f);
  EXPECT_FALSE(tree.nearest_within({0.5f, 0.3f, 0}, 0.25f).has_value());
  EXPECT_EQ(tree.nearest_within({0.9f, 0, 0}, 0.25f)->first, 1u);
}

TEST(KdTree3, WithinFindsEveryPointInTheBall) {
  std::mt19937 rng(11);
  const auto points = random_points(3000, rng);
  const KdTree3 tree(points);
  std::vector<size_t> found;
  for (const auto& q : random_points(200, rng)) {
    tree.within(q, 0.2f, found);
    std::sort(found.begin(), found.end());
    std::vector<size_t> truth;
    for (size_t i = 0; i < points.size(); ++i)
      if ((points[i] - q).norm() < 0.2f) truth.push_back(i);
    EXPECT_EQ(found, truth);
  }
}

}  // namespace
}  // namespace artisan
