// The free-space and visibility check (the private stage that verifies recognition's poses)
// against scenes whose visibility is known exactly. Method: one perspective sensor at the origin
// looking along +z; a table top 1 m away (a plane larger than any model: a background plane), a
// square panel 0.9 m away, and the seen half of a ball of 20 mm radius; every scene point the
// panel or the ball hides from the sensor is left out, as a range sensor would. The model is a
// ball of the same radius resampled at 3 mm, as the model library does. Placed on the seen
// ball, it is explained; where the sensor saw the table through it, it lies in free space;
// behind the panel, it is occluded (no evidence either way); sunk into the table top, it passes
// through a solid's face.
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include <gtest/gtest.h>

#include "artisan/perception/integration.hpp"
#include "artisan/perception/kdtree.hpp"
#include "artisan/perception/spin_image.hpp"
#include "artisan/sim/shapes.hpp"
#include "free_space.hpp"

namespace artisan {
namespace {

constexpr double kRes = 0.003;
constexpr float kRadius = 0.02f;
constexpr float kPanelZ = 0.9f, kTableZ = 1.0f;
const Eigen::Vector3f kSeenBall(-0.1f, 0.0f, 0.95f);  // the ball the sensor saw

// Whether the ray from the sensor (the origin) to p meets the panel (x 0.1 to 0.2 m, y -0.05 to
// 0.05 m at z 0.9 m) or, for a point not on it, the seen ball before p.
bool hidden(const Eigen::Vector3f& p, bool on_ball) {
  const float scale = kPanelZ / p.z();
  if (p.z() > kPanelZ + 1e-4f && std::abs(p.y() * scale) <= 0.05f && p.x() * scale >= 0.1f && p.x() * scale <= 0.2f) return true;
  if (on_ball) return false;  // its sensor-facing half (it is convex)
  // The ray's first meeting with the ball, along the unit direction.
  const Eigen::Vector3f d = p.normalized();
  const float along = d.dot(kSeenBall), off_sq = (kSeenBall - along * d).squaredNorm();
  if (off_sq >= kRadius * kRadius) return false;
  return along - std::sqrt(kRadius * kRadius - off_sq) < p.norm() - 1e-4f;
}

enum class Part { kTable, kPanel, kBall };

struct Scene {
  PointCloud cloud;
  std::vector<Part> part;  ///< per point
};

Scene make_scene() {
  Scene s;
  const auto add = [&](const Eigen::Vector3f& p, const Eigen::Vector3f& n, Part part) {
    if (hidden(p, part == Part::kBall)) return;
    s.cloud.points.push_back(p), s.cloud.normals.push_back(n), s.part.push_back(part);
  };
  const auto step = static_cast<float>(kRes);
  for (float x = -0.3f; x <= 0.3f; x += step)
    for (float y = -0.3f; y <= 0.3f; y += step) add({x, y, kTableZ}, -Eigen::Vector3f::UnitZ(), Part::kTable);
  for (float x = 0.1f; x <= 0.2f; x += step)
    for (float y = -0.05f; y <= 0.05f; y += step) add({x, y, kPanelZ}, -Eigen::Vector3f::UnitZ(), Part::kPanel);
  const PointCloud ball = sample_surface(sim::make_sphere(kRadius, 48), kRes);
  for (size_t i = 0; i < ball.points.size(); ++i) {
    const Eigen::Vector3f p = ball.points[i] + kSeenBall;
    if (ball.normals[i].dot(-p) > 0) add(p, ball.normals[i], Part::kBall);
  }
  return s;
}

Transform at(const Eigen::Vector3f& centre) {
  Transform T = Transform::Identity();
  T.translation() = centre.cast<double>();
  return T;
}

class FreeSpaceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new Scene(make_scene());
    scene_tree_ = new KdTree3(scene_->cloud.points, static_cast<float>(2 * kRes));
    model_ = new PointCloud(sample_surface(sim::make_sphere(kRadius, 48), kRes));
    model_tree_ = new KdTree3(model_->points, static_cast<float>(1.5 * kRes));
  }
  static void TearDownTestSuite() {
    delete model_tree_, delete model_, delete scene_tree_, delete scene_;
  }
  // The check as recognize() sets it up: 3 resolutions of tolerance, every incidence, no
  // support planes, a dropped return at more than 60 degrees no evidence.
  static detail::FreeSpace free_space(const std::vector<SensorView>& views) {
    return detail::FreeSpace(scene_->cloud, *scene_tree_, views, kRes, 3 * kRes, std::numbers::pi / 2, model_->points.size(), 0, true,
                             std::numbers::pi / 3);
  }
  static detail::FreeSpace::Check check(const Eigen::Vector3f& centre) {
    return free_space({SensorView::perspective(Eigen::Vector3d::Zero())}).check({*model_, *model_tree_}, at(centre));
  }
  static Scene* scene_;
  static KdTree3* scene_tree_;
  static PointCloud* model_;
  static KdTree3* model_tree_;
};
Scene* FreeSpaceTest::scene_ = nullptr;
KdTree3* FreeSpaceTest::scene_tree_ = nullptr;
PointCloud* FreeSpaceTest::model_ = nullptr;
KdTree3* FreeSpaceTest::model_tree_ = nullptr;

// A background plane is a plane larger than any model's whole surface: the table top, and the
// panel too (some 1,150 points against the ball's 776); not the ball.
TEST_F(FreeSpaceTest, ThePlanesLargerThanAnyModelAreBackground) {
  const auto fs = free_space({SensorView::perspective(Eigen::Vector3d::Zero())});
  ASSERT_EQ(fs.background().size(), scene_->cloud.points.size());
  std::array<size_t, 3> points{}, flagged{};
  for (size_t i = 0; i < scene_->part.size(); ++i) {
    const auto k = static_cast<size_t>(scene_->part[i]);
    ++points[k];
    flagged[k] += fs.background()[i] != 0;
  }
  ASSERT_GT(points[2], 200u) << "the ball's seen half";
  EXPECT_EQ(flagged[0], points[0]) << "the table top";
  EXPECT_EQ(flagged[1], points[1]) << "the panel";
  EXPECT_EQ(flagged[2], 0u) << "the ball";
  EXPECT_EQ(fs.support(), fs.background()) << "no support planes were asked for";
}

TEST_F(FreeSpaceTest, AModelOnTheSurfaceTheSensorSawIsExplained) {
  const auto c = check(kSeenBall);
  EXPECT_GT(c.explained, 0.95);
  EXPECT_LT(c.free_space, 0.02);
  EXPECT_LT(c.occluded, 0.05);
  EXPECT_LT(c.continued, 0.02) << "the table lies 5 cm behind the ball: the seen surface ends at its outline";
  EXPECT_EQ(c.through, 0.0);
}

TEST_F(FreeSpaceTest, AModelWhereTheSensorSawThroughItLiesInFreeSpace) {
  // Over the open table top, 6 cm in front of it.
  const auto c = check({-0.1f, 0.15f, 0.94f});
  EXPECT_GT(c.free_space, 0.9);
  EXPECT_LT(c.explained, 0.05);
  EXPECT_LT(c.occluded, 0.05);
}

TEST_F(FreeSpaceTest, AModelBehindWhatTheSensorSawIsOccludedNotRefuted) {
  // Between the panel and the table, wholly behind the panel.
  const auto c = check({0.15f, 0.0f, 0.95f});
  EXPECT_LT(c.free_space, 0.02);
  EXPECT_GT(c.occluded, 0.95);
  // Nothing it should show is left to explain it.
  EXPECT_LT(c.explained, 0.05);
}

TEST_F(FreeSpaceTest, AModelSunkIntoTheTableTopPassesThroughASolidsFace) {
  // Half of it under the table top, the half above where the sensor saw the table.
  const auto c = check({-0.1f, -0.15f, kTableZ});
  // Within the tolerance (9 mm) of the face a point counts on neither side: of the ball's
  // surface 27.5% lies farther than that on each side.
  EXPECT_GT(c.through, 0.2);
  EXPECT_LT(c.through, 0.35);
  // With at most 10% through allowed, nothing else is measured: NaN, which no test passes.
  const auto fs = free_space({SensorView::perspective(Eigen::Vector3d::Zero())});
  const auto refused = fs.check({*model_, *model_tree_}, at({-0.1f, -0.15f, kTableZ}), [](const auto&) { return true; }, 0.1);
  EXPECT_GT(refused.through, 0.2);
  EXPECT_TRUE(std::isnan(refused.free_space));
  EXPECT_TRUE(std::isnan(refused.explained));
  EXPECT_TRUE(std::isnan(refused.continued));
  // Resting on the table top (its lowest point on it) it passes through nothing.
  EXPECT_EQ(check({-0.1f, -0.15f, kTableZ - kRadius}).through, 0.0);
}

TEST_F(FreeSpaceTest, TheContinuedSurfaceIsMeasuredOnlyWhenWorthIt) {
  const auto fs = free_space({SensorView::perspective(Eigen::Vector3d::Zero())});
  const auto skipped = fs.check({*model_, *model_tree_}, at(kSeenBall), [](const auto&) { return false; });
  EXPECT_TRUE(std::isnan(skipped.continued));
  EXPECT_GT(skipped.explained, 0.95) << "the rest is measured as before";
}

TEST_F(FreeSpaceTest, WithoutViewsNothingIsEvidenceEitherWay) {
  const auto c = free_space({}).check({*model_, *model_tree_}, at({-0.1f, 0.15f, 0.94f}));
  EXPECT_EQ(c.free_space, 0.0);
  EXPECT_EQ(c.explained, 1.0);
  EXPECT_EQ(c.occluded, 0.0);
}

}  // namespace
}  // namespace artisan
