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

// any_within: whether a point in the ball passes the test, as brute force says.
TEST(KdTree3, AnyWithinAgreesWithBruteForce) {
  std::mt19937 rng(3);
  const auto points = random_points(3000, rng);
  const KdTree3 tree(points);
  size_t yes = 0, no = 0;
  for (const auto& q : random_points(300, rng)) {
    const auto above = [&](size_t i) { return points[i].z() > q.z() + 0.15f; };
    bool truth = false;
    for (size_t i = 0; i < points.size(); ++i) truth = truth || ((points[i] - q).squaredNorm() < 0.2f * 0.2f && above(i));
    EXPECT_EQ(tree.any_within(q, 0.2f, above), truth);
    ++(truth ? yes : no);
  }
  EXPECT_GT(yes, 30u);
  EXPECT_GT(no, 30u);
}

// With a grid of cells for small radii: the same points found as by brute force, for radii read
// from the grid (the nearest up to a cell, every point up to four, any passing a test up to eight)
// and beyond (the tree), queries outside the points' box and NaN queries included.
TEST(KdTree3, TheGridOfCellsFindsWhatBruteForceFinds) {
  std::mt19937 rng(5);
  // Points on a sphere's surface and a plane below it, as a scene's surface lies.
  std::vector<Eigen::Vector3f> points;
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int i = 0; i < 4000; ++i) points.push_back(0.5f * Eigen::Vector3f(g(rng), g(rng), g(rng)).normalized());
  for (int i = 0; i < 4000; ++i) points.push_back({u(rng), u(rng), -0.6f});
  const float cell = 0.05f;
  const KdTree3 tree(points, cell);
  std::vector<size_t> found;
  size_t hits = 0, misses = 0;
  // Queries near the surface (a point moved by about a cell) and anywhere in a box larger than it.
  std::vector<Eigen::Vector3f> queries = random_points(1500, rng);
  for (auto& q : queries) q *= 1.4f;
  for (int i = 0; i < 1500; ++i) queries.push_back(points[rng() % points.size()] + cell * Eigen::Vector3f(g(rng), g(rng), g(rng)));
  for (const auto& query : queries) {
    const auto truth = brute_nearest(points, query);
    for (const float radius : {0.5f * cell, cell, 2.5f * cell, 4.0f * cell, 6.0f * cell}) {
      const auto near = tree.nearest_within(query, radius);
      if (truth.second <= radius * radius) {
        ASSERT_TRUE(near.has_value()) << "radius " << radius;
        EXPECT_FLOAT_EQ(near->second, truth.second);
        EXPECT_FLOAT_EQ((points[near->first] - query).squaredNorm(), truth.second);
        ++hits;
      } else {
        EXPECT_FALSE(near.has_value()) << "radius " << radius;
        ++misses;
      }
      tree.within(query, radius, found);
      std::sort(found.begin(), found.end());
      std::vector<size_t> all;
      for (size_t i = 0; i < points.size(); ++i)
        if ((points[i] - query).squaredNorm() < radius * radius) all.push_back(i);
      EXPECT_EQ(found, all) << "radius " << radius;
      // any_within (the grid up to 8 cells): whether one of them lies above the query.
      const auto above = [&](size_t i) { return points[i].z() > query.z(); };
      EXPECT_EQ(tree.any_within(query, radius, above), std::any_of(all.begin(), all.end(), above)) << "radius " << radius;
    }
  }
  EXPECT_GT(hits, 1000u);
  EXPECT_GT(misses, 1000u);
  const Eigen::Vector3f nan = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
  EXPECT_FALSE(tree.nearest_within(nan, cell).has_value());
  tree.within(nan, cell, found);
  EXPECT_TRUE(found.empty());
  EXPECT_FALSE(tree.nearest_within({100.0f, 0, 0}, cell).has_value());  // far outside the box
  // A point exactly at the radius is taken, as by the tree.
  const KdTree3 two({{0, 0, 0}, {1, 0, 0}}, 0.25f);
  ASSERT_TRUE(two.nearest_within({0.25f, 0, 0}, 0.25f).has_value());
  EXPECT_EQ(two.nearest_within({0.9f, 0, 0}, 0.25f)->first, 1u);
}

// Of points equally near, the grid answers the first it holds (the lowest index among copies of
// one point in one cell), however the copies fall among the four read at a time, and runs of every
// length up to and past a multiple of four.
TEST(KdTree3, TheGridAnswersTheFirstOfEquallyNearPoints) {
  const float cell = 0.01f;
  for (size_t run = 1; run <= 13; ++run)
    for (size_t copy_at = 0; copy_at + 1 < run; ++copy_at) {
      // `run` points in a row in one cell, the nearest at `copy_at` and copied at the run's end,
      // and a point in the next cell.
      std::vector<Eigen::Vector3f> points;
      for (size_t i = 0; i < run; ++i) points.push_back({0.002f + 0.0005f * static_cast<float>(i), 0.005f, 0.005f});
      const Eigen::Vector3f nearest = points[copy_at];
      points.back() = nearest;
      points.push_back({0.015f, 0.005f, 0.005f});
      const KdTree3 grid(points, cell);
      const auto near = grid.nearest_within({nearest.x(), nearest.y(), nearest.z() + 0.001f}, cell);
      ASSERT_TRUE(near.has_value());
      EXPECT_EQ(near->first, copy_at) << "run " << run;
      std::vector<size_t> found;
      grid.within(nearest, 0.0001f, found);
      std::sort(found.begin(), found.end());
      EXPECT_EQ(found, (std::vector<size_t>{copy_at, run - 1})) << "run " << run;
    }
}

// Clouds a grid cannot index (points so far apart that small cells would be too many; a point
// not finite): the tree answers.
TEST(KdTree3, CloudsTheGridCannotIndexAreAnsweredByTheTree) {
  const KdTree3 with_nan({{0, 0, 0}, {std::numeric_limits<float>::quiet_NaN(), 0, 0}, {0.5f, 0, 0}}, 0.25f);
  EXPECT_EQ(with_nan.nearest_within({0.4f, 0, 0}, 0.25f)->first, 2u);
  const std::vector<Eigen::Vector3f> points = {{0, 0, 0}, {0.001f, 0, 0}, {0, 5000, 5000}, {0, 5000.002f, 5000}};
  const KdTree3 tree(points, 0.001f);
  EXPECT_EQ(tree.nearest_within({0.0009f, 0, 0}, 0.001f)->first, 1u);
  EXPECT_EQ(tree.nearest_within({0, 5000.0015f, 5000}, 0.001f)->first, 3u);
  std::vector<size_t> found;
  tree.within({0.0005f, 0, 0}, 0.001f, found);
  std::sort(found.begin(), found.end());
  EXPECT_EQ(found, (std::vector<size_t>{0, 1}));
}

}  // namespace
}  // namespace artisan
