// Recognition's pose hypotheses and their cheap ranking (the private stage between the spin-image
// matches and the ICP) against known poses. Method: the simulator's tee (DN50, resampled at 3 mm
// as the model library does) placed at a known pose, alone or beside a box's faces as clutter.
// The pose from two oriented point pairs gives a known motion back; the surface support counts
// the sampled model points a pose puts on the scene surface, less those explained; pairs of
// spin-image matches, a quarter of them right among wrong ones, propose the true pose; two poses
// of a pipe turned about its axis put its surface in the same place, slid or moved they do not;
// the pool keeps the best of near-duplicate hypotheses.
#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "artisan/perception/kdtree.hpp"
#include "artisan/perception/recognition.hpp"
#include "artisan/perception/spin_image.hpp"
#include "artisan/sim/shapes.hpp"
#include "pose_hypotheses.hpp"

namespace artisan {
namespace {

constexpr double kRes = 0.003;

Transform pose(double angle_rad, const Eigen::Vector3d& axis, const Eigen::Vector3d& t) {
  Transform T = Transform::Identity();
  T.linear() = Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix();
  T.translation() = t;
  return T;
}

PointCloud moved(const PointCloud& cloud, const Transform& T) {
  PointCloud out;
  const Eigen::Isometry3f Tf = T.cast<float>();
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    out.points.push_back(Tf * cloud.points[i]);
    out.normals.push_back(Tf.linear() * cloud.normals[i]);
  }
  return out;
}

double angle_deg(const Transform& a, const Transform& b) { return rotation_angle(a.inverse() * b) * 180 / std::numbers::pi; }
double distance_mm(const Transform& a, const Transform& b) { return 1e3 * (a.translation() - b.translation()).norm(); }

const Transform kTrue = pose(0.7, {1, -2, 0.5}, {0.05, -0.02, 0.9});

TEST(PoseFromPairs, GivesAKnownMotionBack) {
  const Eigen::Vector3f m_a(0.01f, 0.02f, -0.03f), m_b(-0.04f, 0.01f, 0.02f);
  const Eigen::Vector3f nm_a = Eigen::Vector3f(1, 2, 2).normalized(), nm_b = Eigen::Vector3f(-2, 1, 0.5f).normalized();
  const Eigen::Isometry3f T = kTrue.cast<float>();
  const Transform found = detail::pose_from_pairs(m_a, nm_a, m_b, nm_b, T * m_a, T.linear() * nm_a, T * m_b, T.linear() * nm_b,
                                                  (m_b - m_a).norm());
  EXPECT_LT(angle_deg(found, kTrue), 1e-3);
  EXPECT_LT(distance_mm(found, kTrue), 1e-3);
}

class TeeHypotheses : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    model_ = new PointCloud(sample_surface(sim::make_tee(0.2, 0.1), kRes));
    scene_ = new PointCloud(moved(*model_, kTrue));
    // A box's three faces beside the tee (clutter).
    const PointCloud box = sample_surface(sim::make_box({0.1, 0.08, 0.06}), kRes);
    const PointCloud box_at = moved(box, pose(0.3, {0, 0, 1}, {0.2, 0.05, 0.95}));
    tee_points_ = scene_->points.size();
    scene_->points.insert(scene_->points.end(), box_at.points.begin(), box_at.points.end());
    scene_->normals.insert(scene_->normals.end(), box_at.normals.begin(), box_at.normals.end());
    tree_ = new KdTree3(scene_->points, static_cast<float>(2 * kRes));
  }
  static void TearDownTestSuite() { delete tree_, delete scene_, delete model_; }
  static PointCloud* model_;
  static PointCloud* scene_;  ///< the tee at kTrue (its points first, in the model's order), then the box
  static size_t tee_points_;
  static KdTree3* tree_;
};
PointCloud* TeeHypotheses::model_ = nullptr;
PointCloud* TeeHypotheses::scene_ = nullptr;
size_t TeeHypotheses::tee_points_ = 0;
KdTree3* TeeHypotheses::tree_ = nullptr;

TEST_F(TeeHypotheses, TheSurfaceSupportCountsTheModelPointsOnTheSceneLessThoseExplained) {
  const detail::SurfaceSupport support(*model_, 200, *scene_, *tree_);
  const size_t sample = support.first(kTrue, 1.5 * kRes);
  EXPECT_GE(sample, 195u) << "every sampled point lies on the scene at the true pose";
  EXPECT_LE(sample, 210u);
  EXPECT_EQ(support.min_support(0.05), static_cast<size_t>(std::ceil(0.05 * static_cast<double>(sample))));
  // Moved 2 cm across the run, little of it does.
  EXPECT_LT(support.first(pose(0, {0, 0, 1}, {0.02, 0, 0}) * kTrue, 1.5 * kRes), sample / 4);
  // Turned half a turn about its run (z), the branch points the other way: the run still lies on
  // the scene, the branch does not.
  const size_t turned = support.first(kTrue * pose(std::numbers::pi, {0, 0, 1}, {0, 0, 0}), 1.5 * kRes);
  EXPECT_GT(turned, sample / 2);
  EXPECT_LT(turned, sample * 17 / 20);
  // The tee's surface explained by an accepted instance: none of it counts.
  std::vector<char> explained(scene_->points.size(), 0);
  for (size_t i = 0; i < tee_points_; ++i) explained[i] = 1;
  EXPECT_EQ(support(kTrue, 1.5 * kRes, explained), 0u);
  EXPECT_EQ(detail::SurfaceSupport::count(support.lies_on(kTrue, 1.5 * kRes), explained), 0u);
}

TEST_F(TeeHypotheses, PairsOfMatchesProposeTheTruePoseAmongWrongMatches) {
  const detail::SurfaceSupport support(*model_, 200, *scene_, *tree_);
  // 150 tee points matched to their own model point, 450 scene points (tee and box) to a wrong one.
  std::mt19937 rng(7);
  std::vector<detail::Correspondence> matches;
  for (int k = 0; k < 150; ++k) {
    const size_t i = rng() % tee_points_;
    matches.push_back({i, i, 0.9f});
  }
  for (int k = 0; k < 450; ++k) matches.push_back({rng() % model_->points.size(), rng() % scene_->points.size(), 0.8f});
  const RecognitionParams params;
  const auto made = detail::pair_hypotheses(*model_, *scene_, support, matches, kRes, params);
  ASSERT_FALSE(made.empty());
  size_t near_true = 0;
  for (const auto& h : made) {
    EXPECT_GE(h.support, support.min_support(params.pair_min_support)) << "only hypotheses with enough support are kept";
    near_true += angle_deg(h.T_scene_model, kTrue) < 1 && distance_mm(h.T_scene_model, kTrue) < 1;
  }
  EXPECT_GT(near_true, 10u);
  // The best supported is the true pose.
  const auto best = std::max_element(made.begin(), made.end(), [](const auto& a, const auto& b) { return a.support < b.support; });
  EXPECT_LT(angle_deg(best->T_scene_model, kTrue), 1);
  EXPECT_LT(distance_mm(best->T_scene_model, kTrue), 1);
  // Without right matches the true pose is not proposed.
  matches.erase(matches.begin(), matches.begin() + 150);
  for (const auto& h : detail::pair_hypotheses(*model_, *scene_, support, matches, kRes, params))
    EXPECT_FALSE(angle_deg(h.T_scene_model, kTrue) < 1 && distance_mm(h.T_scene_model, kTrue) < 1);
}

TEST(SameSurface, APipeTurnedAboutItsAxisIsTheSameSurfaceSlidOrMovedItIsNot) {
  const PointCloud pipe = sample_surface(sim::make_pipe(0.35), kRes);
  const KdTree3 tree(pipe.points);
  const detail::SameSurface same(pipe, tree);
  EXPECT_NEAR(same.diameter(), pipe.bounds().diagonal().norm(), 1e-6);
  const Transform turned = kTrue * pose(37 * std::numbers::pi / 180, {0, 0, 1}, {0, 0, 0});  // about its own axis (z)
  EXPECT_TRUE(same(kTrue, turned, 2 * kRes));
  EXPECT_LT(same.centre_distance(kTrue, turned), 1e-4);
  const Transform slid = kTrue * pose(0, {0, 0, 1}, {0, 0, 0.01});  // 10 mm along its axis: the ends move
  EXPECT_FALSE(same(kTrue, slid, 2 * kRes));
  const Transform moved_across = kTrue * pose(0, {0, 0, 1}, {0.01, 0, 0});
  EXPECT_FALSE(same(kTrue, moved_across, 2 * kRes));
  EXPECT_NEAR(same.centre_distance(kTrue, moved_across), 0.01, 1e-4);
}

TEST_F(TeeHypotheses, ThePoolKeepsTheBestOfNearDuplicates) {
  const KdTree3 model_tree(model_->points);
  const detail::SameSurface same(*model_, model_tree);
  const auto hypothesis = [](const Transform& T, size_t support) {
    detail::PoseHypothesis h;
    h.T_scene_model = T;
    h.support = support;
    return h;
  };
  const double d = same.diameter();
  std::vector<detail::PoseHypothesis> made = {
      hypothesis(kTrue * pose(0, {0, 0, 1}, {0.001, 0, 0}), 9),                 // 1 mm off the best: a duplicate
      hypothesis(kTrue, 10),                                                     // the best
      hypothesis(kTrue * pose(0.5, {1, 0, 0}, {0, 0, 0}), 8),                    // turned 29 degrees: distinct
      hypothesis(kTrue * pose(0, {0, 0, 1}, {0.5 * d, 0, 0}), 7),                // half a diameter away: distinct
      hypothesis(kTrue * pose(0.1, {0, 1, 0}, {0.05 * d, 0, 0}), 6)};            // near the best: a duplicate
  const auto pool = detail::best_distinct(made, same, 10);
  ASSERT_EQ(pool.size(), 3u);
  EXPECT_EQ(pool[0].support, 10u);
  EXPECT_EQ(pool[1].support, 8u);
  EXPECT_EQ(pool[2].support, 7u);
  EXPECT_EQ(detail::best_distinct(made, same, 2).size(), 2u);
}

}  // namespace
}  // namespace artisan
