// Geometric consistency and grouping of point correspondences (the private stage registration
// and recognition share; Johnson & Hebert, PAMI 1999, section 5), against a known motion.
// Method: the simulator's tee resampled at 3 mm is the target; the source is the same points
// moved by a known rigid motion. 40 true correspondences (a point and its moved self) are mixed
// with 40 false ones (random pairs of points more than 30 mm apart, equally similar). The first
// group must hold only true ones and give the motion back. Grouping again with the agreements
// kept for reuse, less some candidates, must give the same groups.
#include <gtest/gtest.h>

#include <random>

#include <Eigen/Geometry>

#include "artisan/perception/spin_image.hpp"
#include "artisan/sim/shapes.hpp"
#include "correspondence_grouping.hpp"

namespace artisan {
namespace {

constexpr double kRes = 0.003;

struct Problem {
  PointCloud source, target;
  Transform T_target_source = Transform::Identity();
  std::vector<detail::Correspondence> candidates;
  size_t true_count = 0;
};

Problem make_problem() {
  Problem p;
  p.target = sample_surface(sim::make_tee(0.22, 0.11), kRes);
  Transform T_source_target = Transform::Identity();
  T_source_target.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T_source_target.translation() = Eigen::Vector3d(0.3, -0.1, 0.5);
  p.T_target_source = T_source_target.inverse();
  for (size_t i = 0; i < p.target.points.size(); ++i) {
    p.source.points.push_back((T_source_target * p.target.points[i].cast<double>()).cast<float>());
    p.source.normals.push_back((T_source_target.linear() * p.target.normals[i].cast<double>()).cast<float>());
  }
  std::mt19937 rng(7);
  std::uniform_int_distribution<size_t> any(0, p.target.points.size() - 1);
  for (int k = 0; k < 40; ++k) {
    const size_t i = any(rng);
    p.candidates.push_back({i, i, 1.0f});
  }
  p.true_count = p.candidates.size();
  while (p.candidates.size() < 2 * p.true_count) {
    const size_t i = any(rng), j = any(rng);
    if ((p.target.points[i] - p.target.points[j]).norm() > 0.03f) p.candidates.push_back({i, j, 1.0f});
  }
  return p;
}

detail::GroupingParams params() {
  detail::GroupingParams g;
  g.gamma_m = 4 * kRes;
  return g;
}

bool is_true(const detail::Correspondence& c) { return c.source == c.target; }

TEST(CorrespondenceGrouping, TheFirstGroupHoldsOnlyTrueMatchesAndGivesTheMotionBack) {
  const auto p = make_problem();
  const auto result = detail::group_correspondences(p.source, p.target, p.candidates, params());
  ASSERT_FALSE(result.groups.empty());
  const auto& first = result.groups.front();
  EXPECT_GE(first.size, p.true_count / 2);
  for (const auto& c : first.members) EXPECT_TRUE(is_true(c)) << c.source << " -> " << c.target;
  const Transform error = first.T_target_source * p.T_target_source.inverse();
  EXPECT_LT(error.translation().norm(), 1e-4);
  EXPECT_LT(Eigen::AngleAxisd(error.linear()).angle(), 1e-4);
  // Every true match is consistent with enough others to group (the false ones may be too, with
  // a few others by chance: T_gc allows lengths 25% apart).
  EXPECT_GE(result.consistent_candidates, p.true_count);
}

TEST(CorrespondenceGrouping, ReusedAgreementsGiveTheSameGroups) {
  const auto p = make_problem();
  detail::PairAgreements reuse;
  detail::group_correspondences(p.source, p.target, p.candidates, params(), &reuse);
  auto fewer = p.candidates;
  fewer.erase(fewer.begin() + 5, fewer.begin() + 15);  // some explained in between
  const auto fresh = detail::group_correspondences(p.source, p.target, fewer, params());
  const auto reused = detail::group_correspondences(p.source, p.target, fewer, params(), &reuse);
  ASSERT_EQ(fresh.groups.size(), reused.groups.size());
  for (size_t g = 0; g < fresh.groups.size(); ++g) {
    EXPECT_EQ(fresh.groups[g].size, reused.groups[g].size);
    EXPECT_TRUE(fresh.groups[g].T_target_source.matrix().isApprox(reused.groups[g].T_target_source.matrix()));
  }
  EXPECT_EQ(fresh.consistent_candidates, reused.consistent_candidates);
}

}  // namespace
}  // namespace artisan
