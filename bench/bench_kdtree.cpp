// The scene's nearest-point queries: KdTree3 with its grid of cells (as recognition builds it for
// a scene, cells of 2 resolutions) against the same points' k-d tree alone, on a synthetic scene
// like the clutter bench's (a table top 1.0 by 0.6 m and 25 cylinders of 2-5 cm radius, resampled
// to one point per 3 mm cube as the recognizer resamples) with queries as an ICP makes them: batches of 750 about a spot of the scene (70%
// near its surface, 30% off it), each batch asked 15 times. Both must find the same points.
// Output: JSON on stdout.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <random>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "artisan/perception/kdtree.hpp"
#include "artisan/perception/spin_image.hpp"

using namespace artisan;

namespace {

constexpr float kResolution = 0.003f;

std::vector<Eigen::Vector3f> table_scene(std::mt19937& rng) {
  std::uniform_real_distribution<float> u(0, 1);
  std::normal_distribution<float> g(0, 1);
  PointCloud dense;
  for (float x = 0; x < 1.0f; x += 0.001f)
    for (float y = 0; y < 0.6f; y += 0.001f) dense.points.emplace_back(x, y, 0.0f), dense.normals.emplace_back(0.0f, 0.0f, 1.0f);
  for (int c = 0; c < 25; ++c) {
    const Eigen::Vector3f origin(0.05f + 0.9f * u(rng), 0.05f + 0.5f * u(rng), 0.05f);
    const Eigen::Vector3f axis = Eigen::Vector3f(g(rng), g(rng), g(rng)).normalized();
    const Eigen::Vector3f a = axis.unitOrthogonal(), b = axis.cross(a);
    const float radius = 0.02f + 0.03f * u(rng), length = 0.1f + 0.2f * u(rng);
    for (float s = 0; s < length; s += 0.001f)
      for (float t = 0; t < 6.2832f; t += 0.001f / radius) {
        const Eigen::Vector3f out = std::cos(t) * a + std::sin(t) * b;
        dense.points.push_back(origin + s * axis + radius * out);
        dense.normals.push_back(out);
      }
  }
  return resample_oriented_points(dense, kResolution).points;
}

std::vector<Eigen::Vector3f> icp_queries(const std::vector<Eigen::Vector3f>& points, std::mt19937& rng) {
  std::uniform_real_distribution<float> u(0, 1);
  std::normal_distribution<float> g(0, 1);
  const KdTree3 tree(points);
  std::vector<Eigen::Vector3f> queries;
  std::vector<size_t> spot;
  for (int batch = 0; batch < 200; ++batch) {
    const Eigen::Vector3f centre = points[rng() % points.size()];
    tree.within(centre, 0.1f, spot);
    std::vector<Eigen::Vector3f> asked;
    for (int i = 0; i < 750; ++i)
      asked.push_back(u(rng) < 0.7f ? points[spot[rng() % spot.size()]] + 0.004f * Eigen::Vector3f(g(rng), g(rng), g(rng))
                                    : centre + 0.1f * Eigen::Vector3f(g(rng), g(rng), g(rng)));
    for (int iteration = 0; iteration < 15; ++iteration) queries.insert(queries.end(), asked.begin(), asked.end());
  }
  return queries;
}

// Nanoseconds per query (the best of three runs) and a checksum of the answers.
template <typename Query>
std::pair<double, double> timed(const std::vector<Eigen::Vector3f>& queries, size_t stride, const Query& query) {
  double best = std::numeric_limits<double>::infinity(), checksum = 0;
  for (int run = 0; run < 3; ++run) {
    checksum = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (size_t i = 0; i < queries.size(); i += stride) checksum += query(queries[i]);
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return {best / static_cast<double>((queries.size() + stride - 1) / stride) * 1e9, checksum};
}

}  // namespace

int main() {
  std::mt19937 rng(1);
  const auto points = table_scene(rng);
  const auto queries = icp_queries(points, rng);
  const KdTree3 grid(points, 2 * kResolution), tree(points);
  nlohmann::json out = {{"scene_points", points.size()}, {"queries", queries.size()}, {"cell_m", 2 * kResolution}};
  bool same = true;
  // The coarse ICP's radius (2 resolutions), the fine ICP's and visibility tests' (1).
  for (const float radius : {2 * kResolution, kResolution}) {
    const auto nearest = [radius](const KdTree3& t) {
      return [&t, radius](const Eigen::Vector3f& q) {
        const auto near = t.nearest_within(q, radius);
        return near ? static_cast<double>(near->first) : -1.0;
      };
    };
    const auto [grid_ns, grid_sum] = timed(queries, 1, nearest(grid));
    const auto [tree_ns, tree_sum] = timed(queries, 1, nearest(tree));
    same = same && grid_sum == tree_sum;
    const std::string name = "nearest_within_" + std::to_string(static_cast<int>(std::lround(radius * 1000))) + "mm";
    out[name] = {{"grid_ns_per_query", grid_ns}, {"tree_ns_per_query", tree_ns}, {"speedup", tree_ns / grid_ns}};
  }
  // Every point in a ball of 3 resolutions (the visibility tests' silhouette), every tenth query.
  std::vector<size_t> found;
  const auto within = [&found](const KdTree3& t) {
    return [&t, &found](const Eigen::Vector3f& q) {
      t.within(q, 3 * kResolution, found);
      double sum = 0;
      for (const size_t i : found) sum += static_cast<double>(i);
      return sum;
    };
  };
  const auto [grid_ns, grid_sum] = timed(queries, 10, within(grid));
  const auto [tree_ns, tree_sum] = timed(queries, 10, within(tree));
  same = same && grid_sum == tree_sum;
  out["within_9mm"] = {{"grid_ns_per_query", grid_ns}, {"tree_ns_per_query", tree_ns}, {"speedup", tree_ns / grid_ns}};
  out["same_answers"] = same;
  std::cout << out.dump(2) << "\n";
  return same ? 0 : 1;
}
