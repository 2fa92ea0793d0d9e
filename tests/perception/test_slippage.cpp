// Whether a model's surface slides along itself (the private analysis that sets which
// continued-surface limit recognition holds a model to), against the shapes' known motions.
// Method: the simulator's pipework models (DN50) and plain solids, resampled at 3 mm as the
// model library does. A straight pipe slides along its axis and an elbow about its bend (their
// turns about their own axis are no other pose); a flange turns about its axis, but that maps
// it onto itself; a tee, a gate valve, a box and a sphere (every turn a symmetry) do not slide.
#include <gtest/gtest.h>

#include "artisan/perception/spin_image.hpp"
#include "artisan/sim/shapes.hpp"
#include "slippage.hpp"

namespace artisan {
namespace {

constexpr double kRes = 0.003;

bool slides(const TriangleMesh& mesh) { return detail::slides_along_itself(sample_surface(mesh, kRes), kRes); }

TEST(Slippage, APipeAndAnElbowSlideAlongThemselves) {
  EXPECT_TRUE(slides(sim::make_pipe(0.35)));
  EXPECT_TRUE(slides(sim::make_pipe(0.12))) << "a short pipe slides too";
  EXPECT_TRUE(slides(sim::make_elbow(0.076)));
}

TEST(Slippage, PartsHeldByTheirShapeOrTurningOntoThemselvesDoNot) {
  EXPECT_FALSE(slides(sim::make_flange(0.165, 0.02, 0.06))) << "its turn about its axis is a symmetry";
  EXPECT_FALSE(slides(sim::make_tee(0.22, 0.11)));
  EXPECT_FALSE(slides(sim::make_valve(0.24)));
  EXPECT_FALSE(slides(sim::make_box({0.2, 0.1, 0.05})));
  EXPECT_FALSE(slides(sim::make_sphere(0.05))) << "every turn about its centre is a symmetry";
}

TEST(Slippage, NothingToSlideWithoutPointsOrNormals) {
  EXPECT_FALSE(detail::slides_along_itself(PointCloud{}, kRes));
  PointCloud no_normals = sample_surface(sim::make_pipe(0.35), kRes);
  no_normals.normals.clear();
  EXPECT_FALSE(detail::slides_along_itself(no_normals, kRes));
}

}  // namespace
}  // namespace artisan
