// Cylinder-axis pose proposals (the private stage recognition uses for parts made mostly of one
// cylinder, and for round parts' cylinders: a flange's neck) against analytic ground truth.
// Method: the simulator's DN50 pipe (60.3 mm outside, 3.9 mm wall, 350 mm long, along z) resampled at 3 mm; its cylinder must be found about z with
// the outer radius and the length, and the tee, elbow and flange must have none. The pipe's
// sensor-facing half (a sensor above) at a known pose, beside a floor plane, a box and a
// thicker cylinder, is the scene: exactly one axis of the pipe's radius must be found, on the
// pipe's axis, with the seen extent; and among the poses on it one must put the pipe within a
// shift step of its true place. Half the pipe hidden: the extent shrinks to what is seen, and
// a proposal still lies at the true place. A flange's neck is its one round part (its rim too
// short), the tee and elbow have none; a flange seen edge on is proposed on its neck's axis.
#include <gtest/gtest.h>

#include <functional>
#include <numbers>

#include <Eigen/Geometry>

#include "artisan/perception/spin_image.hpp"
#include "artisan/sim/shapes.hpp"
#include "axis_proposals.hpp"

namespace artisan {
namespace {

constexpr double kRes = 0.003;
const double kRadius = sim::PipeSize{}.outer_diameter_m / 2;  // the simulator's DN50 pipe

std::optional<detail::ModelCylinder> cylinder_about_z(const TriangleMesh& mesh, double min_share = 0.8) {
  return detail::model_cylinder(sample_surface(mesh, kRes), Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), kRes, min_share);
}

TEST(AxisProposals, APipeIsACylinderAndTheOtherPartsAreNot) {
  const auto pipe = cylinder_about_z(sim::make_pipe(0.35));
  ASSERT_TRUE(pipe.has_value());
  EXPECT_NEAR(pipe->radius, kRadius, 0.5e-3);  // the facets' points lie up to 0.5% inside the circle
  EXPECT_NEAR(pipe->start, -0.175, 1e-3);
  EXPECT_NEAR(pipe->end, 0.175, 1e-3);
  EXPECT_GT(pipe->share, 0.9);
  EXPECT_TRUE(pipe->round);
  EXPECT_FALSE(cylinder_about_z(sim::make_tee(0.22, 0.11)).has_value());
  EXPECT_FALSE(cylinder_about_z(sim::make_elbow(0.076)).has_value());
  EXPECT_FALSE(cylinder_about_z(sim::make_flange(0.165, 0.02, 0.06)).has_value());
  // The tee's run is a cylinder too, but not most of it; asked for less, it has one, not round.
  const auto tee = cylinder_about_z(sim::make_tee(0.22, 0.11), 0.4);
  ASSERT_TRUE(tee.has_value());
  EXPECT_FALSE(tee->round);
  EXPECT_NEAR(tee->radius, kRadius, 0.5e-3);
}

struct Scene {
  PointCloud points;
  std::vector<char> ignore;
};

// The pipe at T_scene_pipe, the half a sensor above sees (normals up), only where `seen` holds
// (model coordinates), beside a floor, a box and a cylinder 50 mm in radius.
Scene scene_with_pipe(const Transform& T_scene_pipe, const std::function<bool(const Eigen::Vector3f&)>& seen) {
  Scene scene;
  const auto add = [&](const Eigen::Vector3f& p, const Eigen::Vector3f& n, bool ignore) {
    scene.points.points.push_back(p), scene.points.normals.push_back(n), scene.ignore.push_back(ignore);
  };
  const PointCloud pipe = sample_surface(sim::make_pipe(0.35), kRes);
  for (size_t i = 0; i < pipe.points.size(); ++i) {
    const Eigen::Vector3f n = (T_scene_pipe.linear() * pipe.normals[i].cast<double>()).cast<float>();
    const bool bore = pipe.points[i].head<2>().norm() < 0.028f && std::abs(pipe.points[i].z()) < 0.174f;  // hidden inside
    if (n.z() > 0.1f && !bore && seen(pipe.points[i])) add((T_scene_pipe * pipe.points[i].cast<double>()).cast<float>(), n, false);
  }
  for (float x = -0.3f; x <= 0.3f; x += 0.003f)
    for (float y = -0.3f; y <= 0.3f; y += 0.003f) add({x, y, -0.05f}, Eigen::Vector3f::UnitZ(), true);  // a background plane
  for (float x = 0.15f; x <= 0.25f; x += 0.003f)
    for (float y = -0.25f; y <= -0.15f; y += 0.003f) add({x, y, 0.05f}, Eigen::Vector3f::UnitZ(), false);
  for (float y = -0.25f; y <= -0.15f; y += 0.003f)
    for (float z = -0.05f; z <= 0.05f; z += 0.003f) add({0.15f, y, z}, -Eigen::Vector3f::UnitX(), false);
  // A standing cylinder, 50 mm in radius, its side towards -x and its top.
  for (float a = 0.5f * std::numbers::pi_v<float>; a <= 1.5f * std::numbers::pi_v<float>; a += 0.003f / 0.05f)
    for (float z = -0.05f; z <= 0.07f; z += 0.003f) add({-0.2f + 0.05f * std::cos(a), 0.2f + 0.05f * std::sin(a), z}, {std::cos(a), std::sin(a), 0}, false);
  return scene;
}

// How far the pose puts the pipe's axis from the true one: the angle between them, the distance
// of its centre from the true axis and along it from the true centre.
struct AxisError {
  double angle_deg, across_m, along_m;
};
AxisError axis_error(const Transform& T, const Transform& T_true) {
  const Eigen::Vector3d d = T.linear().col(2), d_true = T_true.linear().col(2);
  const Eigen::Vector3d offset = T.translation() - T_true.translation();
  return {std::acos(std::min(1.0, std::abs(d.dot(d_true)))) * 180 / std::numbers::pi, (offset - offset.dot(d_true) * d_true).norm(),
          std::abs(offset.dot(d_true))};
}

TEST(AxisProposals, OneAxisOnTheSeenPipeAndAProposalAtItsPose) {
  const auto pipe = cylinder_about_z(sim::make_pipe(0.35));
  ASSERT_TRUE(pipe.has_value());
  Transform T_scene_pipe = Transform::Identity();
  T_scene_pipe.linear() = (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(std::numbers::pi / 2 - 0.15, Eigen::Vector3d::UnitY()))
                              .toRotationMatrix();  // lying, slightly tilted
  T_scene_pipe.translation() = Eigen::Vector3d(0.02, -0.01, 0.0);
  for (const bool half_hidden : {false, true}) {
    SCOPED_TRACE(half_hidden ? "half hidden" : "whole");
    const Scene scene = scene_with_pipe(T_scene_pipe, [&](const Eigen::Vector3f& p) { return !half_hidden || p.z() > 0.0f; });
    const KdTree3 tree(scene.points.points);
    const auto axes = detail::scene_axes(scene.points, tree, pipe->radius, kRes, scene.ignore, 60);
    ASSERT_EQ(axes.size(), 1u) << "the box, the floor and the thicker cylinder have no axis of the pipe's radius";
    const auto& a = axes.front();
    Transform T_axis = Transform::Identity();
    T_axis.linear() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), a.direction).toRotationMatrix();
    T_axis.translation() = a.point;
    const auto e = axis_error(T_axis, T_scene_pipe);
    EXPECT_LT(e.angle_deg, 2.0);
    EXPECT_LT(e.across_m, 2e-3);
    // The seen extent: the whole pipe, or its half at z > 0 (the points within a sample of the ends).
    EXPECT_NEAR(a.end - a.start, half_hidden ? 0.175 : 0.35, 0.01);
    // Poses: both ways along the axis, a shift every 6 mm over every overlapping placement.
    const auto poses = detail::poses_on_axis(*pipe, a, 2 * kRes, 12);
    const double shifts = std::floor((a.end - a.start + 0.35) / (2 * kRes)) + 1;
    EXPECT_NEAR(static_cast<double>(poses.size()), 2 * shifts, 2.0) << "a round part is not turned";
    double best_along = 1;
    for (const auto& T : poses) {
      const auto p = axis_error(T, T_scene_pipe);
      EXPECT_LT(p.angle_deg, 2.0);
      EXPECT_LT(p.across_m, 2e-3);
      best_along = std::min(best_along, p.along_m);
    }
    EXPECT_LT(best_along, kRes + 2e-3);
  }
}

TEST(AxisProposals, APartThatIsNotRoundIsTurnedAboutTheAxis) {
  const auto tee = cylinder_about_z(sim::make_tee(0.22, 0.11), 0.4);
  ASSERT_TRUE(tee.has_value());
  detail::SceneAxis axis;
  axis.start = -0.05;
  axis.end = 0.05;
  const auto poses = detail::poses_on_axis(*tee, axis, 0.01, 12);
  const double shifts = std::floor((0.1 + tee->end - tee->start) / 0.01) + 1;
  EXPECT_NEAR(static_cast<double>(poses.size()), 2 * 12 * shifts, 2 * 12);
  EXPECT_TRUE(detail::poses_on_axis(*tee, axis, 0.0, 12).empty()) << "a step must be positive";
}

std::vector<detail::ModelCylinder> round_parts_about_z(const TriangleMesh& mesh) {
  return detail::model_round_parts(sample_surface(mesh, kRes), Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), kRes, 0.1);
}

TEST(AxisProposals, AFlangesNeckIsARoundPartAndItsRimIsNot) {
  // The flange: a ring 165 mm across and 20 mm thick, its neck the pipe's radius and 60 mm long.
  const auto parts = round_parts_about_z(sim::make_flange(0.165, 0.02, 0.06));
  ASSERT_EQ(parts.size(), 1u) << "the rim (82.5 mm in radius, 20 mm long) is too short to fix an axis";
  EXPECT_NEAR(parts[0].radius, kRadius, 1e-3);
  EXPECT_NEAR(parts[0].start, 0.02, kRes);  // the samples lie within a spacing of the ends
  EXPECT_NEAR(parts[0].end, 0.08, kRes);
  EXPECT_TRUE(parts[0].round);
  EXPECT_GT(parts[0].share, 0.1);
  EXPECT_TRUE(round_parts_about_z(sim::make_tee(0.22, 0.11)).empty()) << "a tee is not round about its run";
  EXPECT_TRUE(round_parts_about_z(sim::make_elbow(0.076)).empty());
}

TEST(AxisProposals, AFlangeSeenEdgeOnIsProposedOnItsNecksAxis) {
  // A flange lying on its side (its axis along x), seen from above: of its surface only what
  // faces up, its face and back edge on. Its neck's axis must be found, and a pose on it must
  // put the flange at its place.
  const TriangleMesh flange = sim::make_flange(0.165, 0.02, 0.06);
  const auto parts = round_parts_about_z(flange);
  ASSERT_EQ(parts.size(), 1u);
  Transform T_scene_flange = Transform::Identity();
  T_scene_flange.linear() = Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T_scene_flange.translation() = Eigen::Vector3d(0.03, -0.02, 0.0);
  Scene scene;
  const PointCloud points = sample_surface(flange, kRes);
  for (size_t i = 0; i < points.points.size(); ++i) {
    const Eigen::Vector3f n = (T_scene_flange.linear() * points.normals[i].cast<double>()).cast<float>();
    if (n.z() > 0.1f && points.points[i].head<2>().norm() > 0.028f)
      scene.points.points.push_back((T_scene_flange * points.points[i].cast<double>()).cast<float>()), scene.points.normals.push_back(n);
  }
  scene.ignore.assign(scene.points.points.size(), 0);
  const KdTree3 tree(scene.points.points);
  const auto axes = detail::scene_axes(scene.points, tree, parts[0].radius, kRes, scene.ignore, 60);
  ASSERT_FALSE(axes.empty());
  double best_angle = 180, best_across = 1, best_along = 1;
  for (const auto& a : axes)
    for (const auto& T : detail::poses_on_axis(parts[0], a, 2 * kRes, 12)) {
      const auto e = axis_error(T, T_scene_flange);
      if (e.angle_deg >= 2.0 || e.across_m >= 2e-3 || e.along_m >= best_along) continue;
      best_angle = e.angle_deg, best_across = e.across_m, best_along = e.along_m;
    }
  EXPECT_LT(best_along, kRes + 2e-3) << "angle " << best_angle << " deg, " << best_across * 1e3 << " mm across";
}

TEST(AxisProposals, NoAxesWithoutNormalsOrPoints) {
  PointCloud empty;
  const KdTree3 tree(empty.points);
  EXPECT_TRUE(detail::scene_axes(empty, tree, kRadius, kRes, {}, 60).empty());
  EXPECT_FALSE(detail::model_cylinder(empty, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), kRes, 0.8).has_value());
  EXPECT_TRUE(detail::model_round_parts(empty, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), kRes, 0.1).empty());
}

}  // namespace
}  // namespace artisan
