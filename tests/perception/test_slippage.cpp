// Whether a model's surface slides along itself (the private analysis that sets which
// continued-surface limit recognition holds a model to), against the shapes' known motions.
// Method: the simulator's pipework models (DN50) and plain solids, resampled at 3 mm as the
// model library does. A straight pipe slides along its axis and an elbow about its bend (their
// turns about their own axis are no other pose); a flange turns about its axis, but that maps
// it onto itself; a tee, a gate valve, a box and a sphere (every turn a symmetry) do not slide.
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "artisan/perception/spin_image.hpp"
#include "artisan/sim/shapes.hpp"
#include "slippage.hpp"

namespace artisan {
namespace {

constexpr double kRes = 0.003;

bool slides(const TriangleMesh& mesh) { return detail::slide_along_itself(sample_surface(mesh, kRes), kRes).has_value(); }

TEST(Slippage, APipeAndAnElbowSlideAlongThemselves) {
  EXPECT_TRUE(slides(sim::make_pipe(0.35)));
  EXPECT_TRUE(slides(sim::make_pipe(0.12))) << "a short pipe slides too";
  EXPECT_TRUE(slides(sim::make_elbow(0.076)));
}

// The elbow (bend radius 76 mm) is built with its bend centre at (0.076, 0, 0) and the bend in
// the x-z plane: its slide turns it about the y axis through that centre, over a quarter turn.
TEST(Slippage, AnElbowSlidesByTurningAboutItsBendCentre) {
  const PointCloud elbow = sample_surface(sim::make_elbow(0.076), kRes);
  const auto slide = detail::slide_along_itself(elbow, kRes);
  ASSERT_TRUE(slide);
  ASSERT_GT(slide->radius, 0) << "a turn, not a shift";
  EXPECT_GT(std::abs(slide->direction.y()), 0.999) << slide->direction.transpose();
  const Eigen::Vector3d off_axis = (slide->point - Eigen::Vector3d(0.076, 0, 0)).cross(slide->direction);
  EXPECT_LT(off_axis.norm(), 0.002) << "the axis passes " << 1e3 * off_axis.norm() << " mm from the bend centre";
  // The points' RMS distance from the axis: more of the tube's surface lies outside the bend.
  EXPECT_GT(slide->radius, 0.076);
  EXPECT_LT(slide->radius, 0.076 + 0.03);
  EXPECT_NEAR(slide->extent, 0.5 * std::numbers::pi * slide->radius, 4 * kRes) << "a quarter turn at its radius";
  // Slid by 15 mm, the surface stays on itself but for the ends (a sliver of each); shifted by
  // 15 mm along the y axis it does not.
  const KdTree3 tree(elbow.points);
  const double moved = 0.015;
  EXPECT_LT(detail::share_moved_off(elbow, tree, slide->by(moved).cast<float>(), 1.5 * kRes), 0.15);
  EXPECT_NEAR((slide->by(moved) * Eigen::Vector3d(0.076 - slide->radius, 0, 0) - Eigen::Vector3d(0.076 - slide->radius, 0, 0)).norm(), moved, 1e-3);
  EXPECT_GT(detail::share_moved_off(elbow, tree, Eigen::Isometry3f(Eigen::Translation3f(0, 0.015f, 0)), 1.5 * kRes), 0.5);
}

TEST(Slippage, APipeSlidesByAShiftAlongItsAxis) {
  const auto slide = detail::slide_along_itself(sample_surface(sim::make_pipe(0.35), kRes), kRes);
  ASSERT_TRUE(slide);
  // A pipe also turns onto itself about its axis, and the analysis may return the two mixed, as a
  // screw about the axis: either way the axis is the pipe's, and a shift spans its length.
  EXPECT_GT(std::abs(slide->direction.z()), 0.999) << slide->direction.transpose();
  if (slide->radius == 0) {
    EXPECT_NEAR(slide->extent, 0.35, 2 * kRes);
  }
}

TEST(Slippage, PartsHeldByTheirShapeOrTurningOntoThemselvesDoNot) {
  EXPECT_FALSE(slides(sim::make_flange(0.165, 0.02, 0.06))) << "its turn about its axis is a symmetry";
  EXPECT_FALSE(slides(sim::make_tee(0.22, 0.11)));
  EXPECT_FALSE(slides(sim::make_valve(0.24)));
  EXPECT_FALSE(slides(sim::make_box({0.2, 0.1, 0.05})));
  EXPECT_FALSE(slides(sim::make_sphere(0.05))) << "every turn about its centre is a symmetry";
}

TEST(Slippage, NothingToSlideWithoutPointsOrNormals) {
  EXPECT_FALSE(detail::slide_along_itself(PointCloud{}, kRes));
  PointCloud no_normals = sample_surface(sim::make_pipe(0.35), kRes);
  no_normals.normals.clear();
  EXPECT_FALSE(detail::slide_along_itself(no_normals, kRes));
}

}  // namespace
}  // namespace artisan
