// Scoring recognized objects against ground truth (worldmodel/evaluation.hpp), on the world
// fixture: the bunny recognized at a pose known exactly. Method: the truth is that pose, or the
// pose moved by known amounts, and the reported errors are compared with those amounts.
#include <gtest/gtest.h>

#include <numbers>

#include "artisan/core/error.hpp"
#include "artisan/worldmodel/evaluation.hpp"
#include "world_fixture.hpp"

namespace artisan::worldmodel {
namespace {

class EvaluationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ws_ = std::make_unique<Workspace>(Workspace::create(dir_ / "ws.db"));
    fixture_ = test::make_world_fixture(*ws_);
    world_ = std::make_unique<WorldModel>(*ws_, "/cell");
  }
  test::TempDir dir_;
  std::unique_ptr<Workspace> ws_;
  test::WorldFixture fixture_;
  std::unique_ptr<WorldModel> world_;
  const std::vector<std::string> library_ = {"bunny"};
};

TEST_F(EvaluationTest, TheTruePoseIsCorrectWithZeroError) {
  const auto r = evaluate_recognition(*world_, {{"bunny_1", "bunny", fixture_.T_world_bunny, 0.9}}, library_);
  ASSERT_EQ(r.detections.size(), 1u);
  EXPECT_TRUE(r.detections[0].correct);
  EXPECT_EQ(r.detections[0].matched, "bunny_1");
  EXPECT_LT(r.detections[0].rotation_deg, 1e-3);
  EXPECT_LT(r.detections[0].translation_m, 1e-6);
  EXPECT_LT(r.detections[0].mean_distance_m, 1e-6);
  EXPECT_EQ(r.expected, 1);
  EXPECT_EQ(r.found, 1);
  EXPECT_EQ(r.missed, 0);
  EXPECT_EQ(r.false_positives, 0);
}

TEST_F(EvaluationTest, AShiftedTruthGivesItsShiftAndAMiss) {
  // 20 mm along x: the strict translation error is 20 mm, and the surface distance is large
  // enough (the bunny is not symmetric) that the detection is wrong and the object missed.
  const Transform T_true = Transform(Eigen::Translation3d(0.02, 0, 0)) * fixture_.T_world_bunny;
  const auto r = evaluate_recognition(*world_, {{"bunny_1", "bunny", T_true, 0.9}}, library_);
  ASSERT_EQ(r.detections.size(), 1u);
  EXPECT_FALSE(r.detections[0].correct);
  EXPECT_NEAR(r.detections[0].translation_m, 0.02, 1e-6);
  EXPECT_NEAR(r.detections[0].centre_distance_m, 0.02, 1e-6);
  EXPECT_GT(r.detections[0].mean_distance_m, 0.005);
  EXPECT_EQ(r.missed, 1);
  EXPECT_EQ(r.false_positives, 1);
}

TEST_F(EvaluationTest, ASmallRotationIsReportedAndWithinTolerance) {
  // 1 degree about the model's own z axis at its origin: a rotation error of 1 degree, a surface
  // distance of a few tenths of a millimetre on a 0.15 m model.
  const Transform T_true = fixture_.T_world_bunny * Eigen::AngleAxisd(std::numbers::pi / 180, Eigen::Vector3d::UnitZ());
  const auto r = evaluate_recognition(*world_, {{"bunny_1", "bunny", T_true, 0.9}}, library_);
  ASSERT_EQ(r.detections.size(), 1u);
  EXPECT_NEAR(r.detections[0].rotation_deg, 1.0, 1e-6);
  EXPECT_TRUE(r.detections[0].correct);
  EXPECT_LT(r.detections[0].mean_distance_m, 0.003);
}

TEST_F(EvaluationTest, OnlyObjectsSeenEnoughOfKnownModelsAreExpected) {
  const Transform far = Transform(Eigen::Translation3d(0.3, 0.3, 0)) * fixture_.T_world_bunny;
  const std::vector<TrueObject> truth = {{"bunny_1", "bunny", fixture_.T_world_bunny, 0.9},
                                         {"bunny_2", "bunny", far, 0.3},   // hardly seen: not expected
                                         {"bunny_3", "bunny", far, 0.8},   // seen: missed
                                         {"dragon_1", "dragon", far, 1.0},  // not in the library
                                         {"box", "", far, 1.0}};           // a distractor
  const auto r = evaluate_recognition(*world_, truth, library_);
  EXPECT_EQ(r.expected, 2);
  EXPECT_EQ(r.found, 1);
  EXPECT_EQ(r.missed, 1);
  EXPECT_EQ(r.false_positives, 0);
  ASSERT_EQ(r.truth.size(), 5u);
  EXPECT_EQ(r.truth[0].found_as, r.detections[0].path);
  EXPECT_FALSE(r.truth[1].counted);
  EXPECT_TRUE(r.truth[2].counted);
  EXPECT_FALSE(r.truth[3].counted);
  EXPECT_FALSE(r.truth[4].counted);
}

TEST_F(EvaluationTest, BadInputIsRefused) {
  Transform bad = fixture_.T_world_bunny;
  bad.matrix()(0, 3) = std::nan("");
  EXPECT_THROW(evaluate_recognition(*world_, {{"bunny_1", "bunny", bad, 0.9}}, library_), artisan::Error);
  EvaluationParams p;
  p.sample_spacing_m = 0;
  EXPECT_THROW(evaluate_recognition(*world_, {}, library_, p), artisan::Error);
}

}  // namespace
}  // namespace artisan::worldmodel
