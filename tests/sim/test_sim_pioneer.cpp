// The simulated Pioneer trinocular head (real SGBM stereo), its pan/tilt unit, and the
// environmental sensors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include "artisan/core/error.hpp"
#include "artisan/sim/environment.hpp"
#include "artisan/sim/pioneer.hpp"
#include "artisan/sim/simulator.hpp"
#include "sim_test_scenes.hpp"
#include "test_support.hpp"

namespace artisan::sim {
namespace {

using test::at;
using test::box_body;
using test::cell_of;
using test::wall_at;

// Method: a plate 1.0 m in front of the head with a 2 cm square hole on the left camera's axis,
// a wall at 1.5 m, and a 16 mm cube on the wall behind the hole. The left camera sees the cube
// through the hole; the right and top cameras, 0.2 m away, look through the hole at the wall
// 8-11 cm beside it, so neither pair can measure the cube: the ground truth must call it unseen
// (visible fraction 0, though the left image shows it over 20 pixels). A cube in plain view
// of all three cameras, in front of the plate, is visible (above 0.9).
TEST(SimPioneer, WhatOnlyTheLeftCameraSeesIsNotVisible) {
  const double h = 0.01;  // the hole's half-width
  auto cell = cell_of({wall_at(1.5), box_body("plate_left", {0.5 - h, 1.0, 0.01}, at(-(0.5 + h) / 2, 0, 1.0)),
                       box_body("plate_right", {0.5 - h, 1.0, 0.01}, at((0.5 + h) / 2, 0, 1.0)),
                       box_body("plate_top", {2 * h, 0.5 - h, 0.01}, at(0, -(0.5 + h) / 2, 1.0)),
                       box_body("plate_bottom", {2 * h, 0.5 - h, 0.01}, at(0, (0.5 + h) / 2, 1.0)),
                       box_body("hidden", {0.016, 0.016, 0.016}, at(0, 0, 1.49)), box_body("plain", {0.06, 0.06, 0.06}, at(0.2, 0.1, 0.8))});
  Renderer renderer(cell);
  const auto acq = scan_pioneer(renderer, cell, Transform::Identity(), PioneerParams{}, 2);
  const auto object = [&](const std::string& name) {
    const auto it = std::find_if(acq.truth.objects.begin(), acq.truth.objects.end(), [&](const ObjectTruth& o) { return o.name == name; });
    EXPECT_NE(it, acq.truth.objects.end()) << name;
    return *it;
  };
  const auto hidden = object("hidden"), plain = object("plain");
  const auto in_left = std::count(acq.truth.instance_ids.begin(), acq.truth.instance_ids.end(), static_cast<uint16_t>(hidden.instance_id));
  std::printf("cube behind the hole: %ld left-camera pixels, visible fraction %.3f; cube in plain view %.3f\n", static_cast<long>(in_left),
              hidden.visible_fraction, plain.visible_fraction);
  EXPECT_GT(in_left, 20);
  EXPECT_EQ(hidden.visible_pixels, 0);
  EXPECT_GT(plain.visible_fraction, 0.9);
}

// Method: a textured wall at 2.0 m in front of the head, with a textured box 0.5 m nearer.
// Range comes from SGBM on the rendered images, so it is compared with the noise-free render:
// at least 75 % of the pixels must have data, the median depth error must be below 0.5 %
// (SGBM's sub-pixel disparity error of about 0.1 px at d = 59 px is 0.2 %), and 95 % of the
// points must be within 3 % (the rest are the real stereo errors at depth edges).
TEST(SimPioneer, StereoRangeMatchesTruth) {
  auto cell = cell_of({wall_at(2.0), box_body("box", {0.4, 0.4, 0.2}, at(-0.1, 0.05, 1.6))});
  Renderer renderer(cell);
  PioneerParams p;
  const auto acq = scan_pioneer(renderer, cell, Transform::Identity(), p, 3);
  std::vector<double> rel;
  for (size_t i = 0; i < acq.range.pixel_count(); ++i) {
    if (!acq.range.valid[i]) continue;
    rel.push_back(std::abs(acq.range.points_sensor[i].z() - acq.truth.depth_m[i]) / acq.truth.depth_m[i]);
  }
  const double valid = static_cast<double>(rel.size()) / acq.range.pixel_count();
  std::sort(rel.begin(), rel.end());
  const double med = rel[rel.size() / 2], p95 = rel[rel.size() * 95 / 100];
  std::printf("valid %.3f, median relative error %.5f, 95th percentile %.5f\n", valid, med, p95);
  EXPECT_GT(valid, 0.75);
  EXPECT_LT(med, 0.005);
  EXPECT_LT(p95, 0.03);
  ASSERT_EQ(acq.range.images.size(), 3u);
  EXPECT_EQ(acq.range.images[2].name, "top");
  EXPECT_NEAR(acq.range.images[2].T_sensor_camera.translation().y(), -p.baseline_m, 1e-12);
}

// Method: an untextured (flat-shaded) wall gives stereo nothing to match: far fewer pixels
// have data than on the textured wall. This is what makes the stereo errors real.
TEST(SimPioneer, UntexturedSurfacesDefeatStereo) {
  auto textured = cell_of({wall_at(2.0)});
  auto plain = cell_of({wall_at(2.0)});
  plain.bodies[0].material.noise_texture = false;
  Renderer rt(textured), rp(plain);
  const auto a = scan_pioneer(rt, textured, Transform::Identity(), PioneerParams{}, 1);
  const auto b = scan_pioneer(rp, plain, Transform::Identity(), PioneerParams{}, 1);
  std::printf("valid pixels: textured %zu, plain %zu\n", a.range.valid_count(), b.range.valid_count());
  EXPECT_LT(b.range.valid_count() * 3, a.range.valid_count());
}

// Method: in the sample cell, a pan/tilt move changes the head's pose by exactly the commanded
// pan about the unit's vertical axis (tilt 0 both times), advances the clock by the move time
// at the URDF's speed limit (1 rad/s), records the angles, and angles beyond the limits throw.
TEST(SimPioneer, PanTiltMovesTheHeadAndRespectsLimits) {
  Simulator sim(load_workcell(artisan::test::data_dir() / "workcells" / "pipework.json"));
  ScanRequest req;
  req.sensor = "pioneer";
  req.pan_rad = 0.2;
  req.tilt_rad = 0.0;
  const auto a = sim.scan(req);
  const double t_a = sim.clock_s();
  req.pan_rad = 0.7;
  const auto b = sim.scan(req);
  EXPECT_NEAR(b.truth.time_s - t_a, 0.5 / 1.0 + pioneer_params({}).settle_time_s, 1e-6);  // clock ~1e9 s: ulp 1e-7
  const Transform rel = a.truth.T_world_sensor.inverse() * b.truth.T_world_sensor;
  EXPECT_NEAR(rotation_angle(rel), 0.5, 1e-6);
  EXPECT_NEAR(b.truth.joint_values.at("ptu_pan"), 0.7, 1e-12);
  ASSERT_TRUE(b.truth.environment.has_value());
  EXPECT_GT(b.range.valid_count(), b.range.pixel_count() / 3);
  req.pan_rad = 3.0;
  EXPECT_THROW(sim.scan(req), Error);
  req.pan_rad.reset();
  req.tilt_rad = -0.9;
  EXPECT_THROW(sim.scan(req), Error);
  ScanRequest vivid;
  vivid.sensor = "vivid";
  vivid.pan_rad = 0.1;
  EXPECT_THROW(sim.scan(vivid), Error);  // not on a pan/tilt unit
}

// Method: gamma dose rate against the closed-form law. One 100 µSv/h-at-1-m source, air
// attenuation off: 25 µSv/h at 2 m (inverse square). A 5 cm steel slab (60 /m) between source
// and detector: the path length through it is 5 cm, and the dose drops by exp(-3).
TEST(SimEnvironment, DoseRateFollowsInverseSquareAndAttenuation) {
  auto cell = cell_of({});
  cell.environment.air_attenuation_per_m = 0.0;
  cell.environment.gamma_sources.push_back({"s", Eigen::Vector3d(0, 0, 1), 100.0});
  EXPECT_NEAR(dose_rate_uSv_per_h(cell, {0, 0, 2}), 100.0, 1e-9);
  EXPECT_NEAR(dose_rate_uSv_per_h(cell, {0, 2, 1}), 25.0, 1e-9);
  auto shielded = cell_of({box_body("slab", {1, 0.05, 1}, at(0, 1, 1))});
  shielded.environment = cell.environment;
  EXPECT_NEAR(path_length_in_bodies(shielded, {0, 0, 1}, {0, 2, 1}), 0.05, 1e-9);
  EXPECT_NEAR(dose_rate_uSv_per_h(shielded, {0, 2, 1}), 25.0 * std::exp(-60.0 * 0.05), 1e-6);
  // Fields and noise: readings scatter about the field values with the given sigma, and
  // repeat for a seed.
  cell.environment.temperature_C.gradient = Eigen::Vector3d(0, 0, 1.0);
  const auto r1 = read_environment(cell, at(0, 0, 2), 5.0, EnvironmentSensorParams{}, 7);
  const auto r2 = read_environment(cell, at(0, 0, 2), 5.0, EnvironmentSensorParams{}, 7);
  EXPECT_EQ(r1.temperature_C, r2.temperature_C);
  EXPECT_NEAR(r1.temperature_C, 22.0, 0.5);
  EXPECT_NEAR(r1.dose_rate_uSv_per_h, 100.0, 25.0);
  EXPECT_EQ(r1.time_s, 5.0);
}

}  // namespace
}  // namespace artisan::sim
