// Transforms: parsing the command-line forms, the JSON form, and the T_a_b convention.
#include <gtest/gtest.h>

#include <numbers>

#include "artisan/core/error.hpp"
#include "artisan/core/pose.hpp"

namespace artisan {
namespace {

TEST(Pose, SevenNumbersAreTranslationAndUnitQuaternionWLast) {
  // 90 degrees about z: q = (0, 0, sin 45, cos 45).
  const double s = std::sqrt(0.5);
  const Transform T = parse_transform("1 2 3 0 0 " + std::to_string(s) + " " + std::to_string(s));
  EXPECT_TRUE(T.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  // x axis maps to y axis.
  EXPECT_TRUE((T.linear() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), 1e-6));
  EXPECT_NEAR(rotation_angle(T), std::numbers::pi / 2, 1e-6);
}

TEST(Pose, SixteenNumbersAreRowMajorAndRoundTrip) {
  Transform T = Transform::Identity();
  T.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.1, -0.2, 0.3);
  const auto m = to_row_major(T);
  EXPECT_DOUBLE_EQ(m[3], 0.1);  // row-major: translation x is the 4th entry
  EXPECT_DOUBLE_EQ(m[15], 1.0);
  std::string text;
  for (double v : m) text += std::to_string(v) + ",";
  const Transform back = from_row_major(m);
  EXPECT_TRUE(back.isApprox(T, 1e-12));
  EXPECT_TRUE(parse_transform(text).isApprox(T, 1e-5));
}

TEST(Pose, CompositionFollowsTheNamingConvention) {
  const Transform T_a_b = parse_transform("1 0 0 0 0 0 1");
  const Transform T_b_c = parse_transform("0 1 0 0 0 0.7071067811865476 0.7071067811865476");
  const Transform T_a_c = T_a_b * T_b_c;
  const Eigen::Vector3d p_c(1, 0, 0);
  EXPECT_TRUE((T_a_c * p_c).isApprox(T_a_b * (T_b_c * p_c)));
  EXPECT_TRUE((T_a_c * p_c).isApprox(Eigen::Vector3d(1, 2, 0), 1e-9));
}

TEST(Pose, BadInputThrowsNamingTheText) {
  for (const std::string bad : {"", "1 2 3", "1 2 3 0 0 0 2", "1 2 x 0 0 0 1", "1 2 3 0 0 0 nan",
                                "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 2", "2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1",
                                "-1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"}) {
    try {
      parse_transform(bad);
      ADD_FAILURE() << "accepted \"" << bad << "\"";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("pose"), std::string::npos) << e.what();
    }
  }
}

TEST(Pose, NearlyUnitQuaternionIsNormalised) {
  const Transform T = parse_transform("0 0 0 0 0 0 1.0005");
  EXPECT_TRUE(T.linear().isApprox(Eigen::Matrix3d::Identity()));
}

}  // namespace
}  // namespace artisan
