// The simulated Minolta Vivid 700: noise statistics, shadowing, grazing dropouts, determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "artisan/core/error.hpp"
#include "artisan/sim/vivid.hpp"
#include "sim_test_scenes.hpp"

namespace artisan::sim {
namespace {

using test::at;
using test::box_body;
using test::cell_of;
using test::wall_at;

VividParams no_random_dropouts() {
  VividParams p;
  p.random_dropout = 0.0;
  return p;
}

// Method: a fronto-parallel wall at d = 1.0 m and at 2.0 m fills the view. The residual z - d
// of every valid pixel is the model's noise (the noise-free render is exact to microns, see
// test_sim_render): its standard deviation must match sigma(d) = 0.8 mm (d / 1 m)^2 within 4 %
// (40,000 samples give a standard error of 0.35 %), its mean must be 0 within 4 standard
// errors, and the noise must grow fourfold from 1 m to 2 m.
TEST(SimVivid, RangeNoiseMatchesTheModel) {
  const VividParams p = no_random_dropouts();
  double sigma_measured[2] = {0, 0};
  int k = 0;
  for (double d : {1.0, 2.0}) {
    auto cell = cell_of({wall_at(d)});
    Renderer renderer(cell);
    const auto acq = scan_vivid(renderer, cell, Transform::Identity(), p, 11);
    double sum = 0, sum2 = 0;
    int n = 0;
    for (size_t i = 0; i < acq.range.pixel_count(); ++i) {
      if (!acq.range.valid[i]) continue;
      const double e = acq.range.points_sensor[i].z() - d;
      sum += e;
      sum2 += e * e;
      ++n;
    }
    ASSERT_GT(n, 39000);
    const double mean = sum / n, sigma = std::sqrt(sum2 / n - mean * mean);
    const double model = vivid_range_sigma(p, d);
    std::printf("d = %.1f m: %d points, mean %.2e m, sigma %.4f mm (model %.4f mm)\n", d, n, mean, sigma * 1e3, model * 1e3);
    EXPECT_NEAR(sigma / model, 1.0, 0.04);
    EXPECT_LT(std::abs(mean), 4 * model / std::sqrt(n));
    sigma_measured[k++] = sigma;
  }
  EXPECT_NEAR(sigma_measured[1] / sigma_measured[0], 4.0, 0.2);
}

// Method: a 10 cm cube 0.55 m in front of a wall at 1.5 m; the laser emitter sits 0.15 m above
// the camera (-y). For every wall pixel, the segment from the emitter to the wall point is
// tested analytically against the cube: pixels whose segment crosses the cube (shrunk by 5 mm,
// to leave the boundary pixels out) must have no data; pixels whose segment clears the cube
// grown by 5 mm must have data. The shadow must be a substantial region (it is below the cube's
// image: the laser comes from above).
TEST(SimVivid, LaserShadowMatchesGeometry) {
  const VividParams p = no_random_dropouts();
  const Eigen::Vector3d cube_centre(0, 0, 0.9), half(0.05, 0.05, 0.05);
  auto cell = cell_of({wall_at(1.5), box_body("cube", 2 * half, at(cube_centre.x(), cube_centre.y(), cube_centre.z()))});
  Renderer renderer(cell);
  const auto acq = scan_vivid(renderer, cell, Transform::Identity(), p, 5);
  const Eigen::Vector3d emitter(0, -p.baseline_m, 0);
  auto crosses = [&](const Eigen::Vector3d& target, double grow) {
    const Eigen::Vector3d d = target - emitter;
    double t0 = 0, t1 = 1;
    for (int k = 0; k < 3; ++k) {
      double ta = (cube_centre[k] - half[k] - grow - emitter[k]) / d[k], tb = (cube_centre[k] + half[k] + grow - emitter[k]) / d[k];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    return t0 <= t1;
  };
  int shadowed = 0, wrong = 0, lit_checked = 0;
  for (int v = 0; v < acq.truth.camera.height; ++v)
    for (int u = 0; u < acq.truth.camera.width; ++u) {
      const size_t i = acq.range.index(u, v);
      if (acq.truth.instance_ids[i] != 1) continue;  // wall pixels only
      const Eigen::Vector3d q = acq.truth.camera.unproject({u, v}, acq.truth.depth_m[i]);
      if (crosses(q, -0.005)) {
        ++shadowed;
        wrong += acq.range.valid[i] != 0;
      } else if (!crosses(q, 0.005)) {
        ++lit_checked;
        wrong += acq.range.valid[i] == 0;
      }
    }
  std::printf("shadowed wall pixels %d, lit wall pixels checked %d, disagreements %d\n", shadowed, lit_checked, wrong);
  EXPECT_GT(shadowed, 300);
  EXPECT_GT(lit_checked, 30000);
  EXPECT_EQ(wrong, 0);
}

// Method: a wall turned away from the camera about y. In a central strip (|u - cx| <= 8
// pixels, incidence within about 1.2 degrees of the turn angle) the fraction of valid pixels
// must follow the model's linear ramp from 60 to 80 degrees: all valid at 30, about 1 - 0.49 at
// 70, none at 85.
TEST(SimVivid, GrazingSurfacesDropOut) {
  const VividParams p = no_random_dropouts();
  for (double deg : {30.0, 70.0, 85.0}) {
    const double a = deg * M_PI / 180;
    auto cell = cell_of({wall_at(1.2, a)});
    Renderer renderer(cell);
    const auto acq = scan_vivid(renderer, cell, Transform::Identity(), p, 9);
    int n = 0, valid = 0;
    for (int v = 40; v < 160; ++v)
      for (int u = 92; u <= 108; ++u) {
        const size_t i = acq.range.index(u, v);
        if (acq.truth.depth_m[i] <= 0 || acq.truth.depth_m[i] > p.max_range_m || acq.truth.depth_m[i] < p.min_range_m) continue;
        ++n;
        valid += acq.range.valid[i];
      }
    ASSERT_GT(n, 500) << deg;
    const double expected = 1.0 - std::clamp((a - p.grazing_start_rad) / (p.grazing_limit_rad - p.grazing_start_rad), 0.0, 1.0);
    std::printf("turned %.0f deg: valid fraction %.3f (model %.3f)\n", deg, static_cast<double>(valid) / n, expected);
    EXPECT_NEAR(static_cast<double>(valid) / n, expected, 0.08) << deg;
  }
}

// Method: the same scene and seed give bit-identical range images; another seed does not.
TEST(SimVivid, DeterministicForASeed) {
  auto cell = cell_of({wall_at(1.4), box_body("cube", {0.2, 0.2, 0.2}, at(0.1, 0.0, 1.1))});
  Renderer renderer(cell);
  const auto a = scan_vivid(renderer, cell, Transform::Identity(), VividParams{}, 42);
  const auto b = scan_vivid(renderer, cell, Transform::Identity(), VividParams{}, 42);
  const auto c = scan_vivid(renderer, cell, Transform::Identity(), VividParams{}, 43);
  EXPECT_TRUE(a.range == b.range);
  EXPECT_FALSE(a.range == c.range);
  EXPECT_EQ(a.range.width, 200);
  EXPECT_EQ(a.range.images.at(0).image.width, 400);
  EXPECT_EQ(a.range.sensor.kind, "minolta-vivid-700");
}

// Method: a 3 cm cube against the wall, in the laser shadow of the 10 cm cube of the test above
// (the wall's shadow there spans y = 0.01 to 0.2 m; the camera sees past the big cube's image up
// to y = 0.09 m on the wall, so the small cube at y = 0.135 to 0.165 m is in plain view of the
// camera and lit by nothing). The scanner measures nothing on it, so the ground truth must call
// it unseen: visible fraction 0 though the camera's instance image shows it over 50 pixels. The
// big cube, lit, is all visible.
TEST(SimVivid, WhatTheLaserCannotReachIsNotVisible) {
  auto cell = cell_of({wall_at(1.5), box_body("cube", {0.1, 0.1, 0.1}, at(0, 0, 0.9)), box_body("small", {0.03, 0.03, 0.03}, at(0, 0.15, 1.47))});
  Renderer renderer(cell);
  const auto acq = scan_vivid(renderer, cell, Transform::Identity(), no_random_dropouts(), 5);
  const auto& big = acq.truth.objects.at(1);
  const auto& small = acq.truth.objects.at(2);
  ASSERT_EQ(small.name, "small");
  const auto in_image = std::count(acq.truth.instance_ids.begin(), acq.truth.instance_ids.end(), static_cast<uint16_t>(small.instance_id));
  size_t measured = 0;
  for (size_t i = 0; i < acq.range.pixel_count(); ++i) measured += acq.truth.instance_ids[i] == small.instance_id && acq.range.valid[i];
  std::printf("small cube: %ld camera pixels, %zu measured, visible fraction %.3f; big cube %.3f\n", static_cast<long>(in_image), measured,
              small.visible_fraction, big.visible_fraction);
  EXPECT_GT(in_image, 50);
  EXPECT_EQ(measured, 0u);
  EXPECT_EQ(small.visible_pixels, 0);
  EXPECT_EQ(small.visible_fraction, 0.0);
  EXPECT_GT(big.visible_fraction, 0.95);
}

// Method: a 10 x 10 cm plate 3 mm thick, 1 m in front of the camera, turned about y. Faced at 30
// degrees it is all visible. Turned 85 degrees its face lies beyond the scanner's grazing limit
// (80 degrees, where every return drops out): the camera sees the face over more pixels than its
// edge, but the scanner measures none of it, so the ground truth must count the face as hidden
// (visible fraction under 0.4) - not as a face the recognizer failed to find.
TEST(SimVivid, WhatTheScannerNeverReturnsIsNotVisible) {
  const auto plate = [](double deg) {
    Transform T = at(0, 0, 1.0);
    T.rotate(Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitY()));
    auto cell = cell_of({wall_at(1.6), box_body("plate", {0.1, 0.1, 0.003}, T)});
    Renderer renderer(cell);
    const auto acq = scan_vivid(renderer, cell, Transform::Identity(), no_random_dropouts(), 4);
    const auto& o = acq.truth.objects.at(1);
    EXPECT_EQ(o.name, "plate");
    size_t measured = 0;
    for (size_t i = 0; i < acq.range.pixel_count(); ++i) measured += acq.truth.instance_ids[i] == o.instance_id && acq.range.valid[i];
    std::printf("plate turned %.0f deg: %d pixels alone, %d visible, %zu measured, visible fraction %.3f\n", deg, o.unoccluded_pixels,
                o.visible_pixels, measured, o.visible_fraction);
    EXPECT_LE(measured, static_cast<size_t>(o.visible_pixels));
    return o.visible_fraction;
  };
  EXPECT_GT(plate(30), 0.97);
  EXPECT_LT(plate(85), 0.4);
}

// Method: the ground truth's visible fraction counts what lies outside the sensor's frame as
// hidden. A 10 cm cube 0.95 m in front of the camera (focal length 391.6 px, 200 px wide: the
// frame's right edge is at x = 0.2553 z), centred on that edge, shows its left face (about 8 px
// wide) and the left half of its front face (about 20 of 41 px) in the frame: 0.5 to 0.65 of
// what it would show on a wider image plane. The same cube moved into the frame shows all of it;
// moved out of it, nothing (and still covers pixels when rendered alone on the wider plane).
TEST(SimVivid, VisibleFractionCountsWhatLiesOutsideTheFrameAsHidden) {
  const double edge_x = 0.2553 * 0.95;
  const auto fraction = [](double x, int* unoccluded = nullptr) {
    auto cell = cell_of({wall_at(1.6), box_body("cube", {0.1, 0.1, 0.1}, at(x, 0.0, 1.0))});
    Renderer renderer(cell);
    const auto acq = scan_vivid(renderer, cell, Transform::Identity(), no_random_dropouts(), 3);
    const auto& cube = acq.truth.objects.at(1);
    EXPECT_EQ(cube.name, "cube");
    if (unoccluded) *unoccluded = cube.unoccluded_pixels;
    return cube.visible_fraction;
  };
  const double at_edge = fraction(edge_x);
  std::printf("visible fraction of the cube on the frame's edge: %.3f\n", at_edge);
  EXPECT_GT(at_edge, 0.5);
  EXPECT_LT(at_edge, 0.65);
  EXPECT_NEAR(fraction(0.0), 1.0, 1e-9);
  int unoccluded = 0;
  EXPECT_EQ(fraction(edge_x + 0.1, &unoccluded), 0.0);
  EXPECT_GT(unoccluded, 1000);
}

// Method: out-of-range surfaces give no data: a wall at 3 m is beyond the 2.5 m standoff.
TEST(SimVivid, NothingBeyondTheStandoff) {
  auto cell = cell_of({wall_at(3.0)});
  Renderer renderer(cell);
  const auto acq = scan_vivid(renderer, cell, Transform::Identity(), VividParams{}, 1);
  EXPECT_EQ(acq.range.valid_count(), 0u);
  EXPECT_GT(std::count_if(acq.truth.depth_m.begin(), acq.truth.depth_m.end(), [](float z) { return z > 0; }), 39000);
}

// Method: unknown parameter names are refused.
TEST(SimVivid, UnknownParameterThrows) {
  EXPECT_THROW(vivid_params({{"baseline", 0.1}}), Error);
  EXPECT_DOUBLE_EQ(vivid_params({{"baseline_m", 0.1}}).baseline_m, 0.1);
}

}  // namespace
}  // namespace artisan::sim
