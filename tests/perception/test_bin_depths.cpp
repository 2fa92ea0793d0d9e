// The free-space test's depth bins (private to recognition): each bin's nearest depth, and with
// a spread the nearest in the 3 x 3 bins about it, against the minimum taken directly over the
// depths given; kept in an array over a compact range and in a table over a sparse one, with the
// same answers.
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "bin_depths.hpp"

namespace artisan {
namespace {

using detail::BinDepths;
constexpr double kNone = std::numeric_limits<double>::infinity();

// The nearest depth within `spread` bins of (u, v), taken directly.
double nearest(const std::vector<BinDepths::Binned>& binned, int64_t u, int64_t v, int spread) {
  double best = kNone;
  for (const auto& b : binned)
    if (std::abs(b.u - u) <= spread && std::abs(b.v - v) <= spread) best = std::min(best, b.depth);
  return best;
}

std::vector<BinDepths::Binned> random_depths(int64_t u0, int64_t v0, int64_t span, size_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int64_t> bin(0, span - 1);
  std::uniform_real_distribution<double> depth(0.5, 2.0);
  std::vector<BinDepths::Binned> binned;
  for (size_t k = 0; k < count; ++k) binned.push_back({u0 + bin(rng), v0 + bin(rng), depth(rng)});
  return binned;
}

// Every bin of the range and a margin about it, against the direct minimum.
void expect_nearest(const BinDepths& depths, const std::vector<BinDepths::Binned>& binned, int spread, int64_t u0, int64_t v0, int64_t span) {
  for (int64_t u = u0 - 3; u < u0 + span + 3; ++u)
    for (int64_t v = v0 - 3; v < v0 + span + 3; ++v) ASSERT_EQ(depths.at(u, v), nearest(binned, u, v, spread)) << "bin " << u << ", " << v;
}

TEST(BinDepths, ACompactRangeIsAnArrayWithEachBinsNearestDepth) {
  // Bins about negative and positive indices, several depths in many bins.
  const auto binned = random_depths(-20, -7, 40, 600, 1);
  for (const int spread : {0, 1}) {
    BinDepths depths;
    depths.assign(binned, spread);
    EXPECT_TRUE(depths.dense());
    expect_nearest(depths, binned, spread, -20, -7, 40);
  }
}

TEST(BinDepths, ASparseRangeIsATableWithTheSameAnswers) {
  // Two clusters a million bins apart: an array over the range would hold 10^12 bins.
  auto binned = random_depths(-5, -5, 12, 100, 2);
  const auto far = random_depths(1'000'000, 1'000'000, 12, 100, 3);
  binned.insert(binned.end(), far.begin(), far.end());
  for (const int spread : {0, 1}) {
    BinDepths depths;
    depths.assign(binned, spread);
    EXPECT_FALSE(depths.dense());
    expect_nearest(depths, binned, spread, -5, -5, 12);
    expect_nearest(depths, binned, spread, 1'000'000, 1'000'000, 12);
    EXPECT_EQ(depths.at(500'000, 500'000), kNone) << "between the clusters nothing was seen";
  }
}

TEST(BinDepths, AssignedAgainItForgetsTheLastDepths) {
  BinDepths depths;
  depths.assign({{0, 0, 1.0}, {3, 3, 2.0}});
  EXPECT_EQ(depths.at(0, 0), 1.0);
  depths.assign({{3, 3, 1.5}});
  EXPECT_EQ(depths.at(0, 0), kNone);
  EXPECT_EQ(depths.at(3, 3), 1.5);
  depths.assign({});
  EXPECT_EQ(depths.at(3, 3), kNone) << "nothing seen anywhere";
}

}  // namespace
}  // namespace artisan
