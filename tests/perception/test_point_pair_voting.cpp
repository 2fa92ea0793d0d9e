// Point-pair-feature voting (the private stage recognition uses for pose hypotheses) against
// ground truth. Method: the bunny model (Stanford's reconstruction), resampled, placed in a
// synthetic scene at a known pose beside a table plane and a box, only the side a sensor above
// would see kept; the best vote cluster must be the true pose within the quantisation (alpha
// bins of 12 degrees, a 6 mm step: within 6 degrees and 6 mm after the cluster mean). Scene
// points marked to ignore do not vote; crowded cells are left out of the table; bad parameters throw.
#include <gtest/gtest.h>

#include <limits>
#include <numbers>

#include <Eigen/Geometry>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/perception/spin_image.hpp"
#include "point_pair_voting.hpp"
#include "test_support.hpp"

namespace artisan {
namespace {

PointCloud bunny_points() {
  const auto path = test::bunny_dir() / "reconstruction" / "bun_zipper.ply";
  return sample_surface(io::ply_to_mesh(io::read_ply(path), path), 0.003);
}

// The bunny at T_scene_model, the half facing +z (a sensor above), on a plane of clutter and
// beside a box's faces; `ignore` marks the bunny's points when `ignore_bunny`.
PointCloud scene_with(const PointCloud& model, const Transform& T_scene_model, std::vector<char>& ignore, bool ignore_bunny) {
  PointCloud scene;
  ignore.clear();
  for (size_t i = 0; i < model.points.size(); ++i) {
    const Eigen::Vector3f n = (T_scene_model.linear() * model.normals[i].cast<double>()).cast<float>();
    if (n.z() <= 0.1f) continue;
    scene.points.push_back((T_scene_model * model.points[i].cast<double>()).cast<float>());
    scene.normals.push_back(n);
    ignore.push_back(ignore_bunny);
  }
  const auto add = [&](const Eigen::Vector3f& p, const Eigen::Vector3f& n) {
    scene.points.push_back(p), scene.normals.push_back(n), ignore.push_back(0);
  };
  for (float x = -0.3f; x <= 0.3f; x += 0.003f)
    for (float y = -0.3f; y <= 0.3f; y += 0.003f) add({x, y, -0.08f}, Eigen::Vector3f::UnitZ());
  for (float x = 0.15f; x <= 0.25f; x += 0.003f)
    for (float y = -0.05f; y <= 0.05f; y += 0.003f) add({x, y, 0.02f}, Eigen::Vector3f::UnitZ());
  for (float y = -0.05f; y <= 0.05f; y += 0.003f)
    for (float z = -0.08f; z <= 0.02f; z += 0.003f) add({0.15f, y, z}, -Eigen::Vector3f::UnitX());
  return scene;
}

TEST(PointPairVoting, TheBestClusterIsTheTruePose) {
  const PointCloud model = bunny_points();
  detail::PairVotingParams params;  // 6 mm step: 0.03 of the bunny's diameter
  const detail::PairFeatureModel table(model, params);
  EXPECT_GT(table.pairs(), 100000u);
  for (const auto& [axis, angle_deg] : {std::pair{Eigen::Vector3d(0, 0, 1), 35.0}, {Eigen::Vector3d(1, 1, 0).normalized(), 120.0},
                                        {Eigen::Vector3d(1, -2, 3).normalized(), -70.0}}) {
    Transform T_scene_model = Transform::Identity();
    T_scene_model.linear() = Eigen::AngleAxisd(angle_deg * std::numbers::pi / 180, axis).toRotationMatrix();
    T_scene_model.translation() = Eigen::Vector3d(-0.05, 0.02, 0.03) - T_scene_model.linear() * model.bounds().center().cast<double>();
    std::vector<char> ignore;
    const PointCloud scene = scene_with(model, T_scene_model, ignore, false);
    const auto poses = table.vote(scene, ignore);
    ASSERT_FALSE(poses.empty());
    const Transform e = T_scene_model.inverse() * poses.front().T_scene_model;
    EXPECT_LT(rotation_angle(e) * 180 / std::numbers::pi, 6.0) << "turned " << angle_deg << " degrees";
    EXPECT_LT(e.translation().norm(), 0.006) << "turned " << angle_deg << " degrees";
    EXPECT_GT(poses.front().votes, 2 * poses[1].votes) << "the true pose does not stand out";

    // The same scene with the bunny's points ignored: no cluster near the pose stands out.
    const auto without = table.vote(scene_with(model, T_scene_model, ignore, true), ignore);
    for (const auto& p : without)
      EXPECT_FALSE(rotation_angle(T_scene_model.inverse() * p.T_scene_model) < 0.1 &&
                   (p.T_scene_model.translation() - T_scene_model.translation()).norm() < 0.006 && p.votes >= poses.front().votes / 4);
  }
}

TEST(PointPairVoting, CrowdedCellsAreLeftOut) {
  // A flat square: every pair has the same three angles, so a few cells hold all the pairs.
  PointCloud plane;
  for (float x = 0; x <= 0.1f; x += 0.003f)
    for (float y = 0; y <= 0.1f; y += 0.003f) plane.points.push_back({x, y, 0}), plane.normals.push_back(Eigen::Vector3f::UnitZ());
  detail::PairVotingParams params;
  params.step_m = 0.006;
  params.max_cell_share = 1.0;
  const detail::PairFeatureModel all(plane, params);
  EXPECT_EQ(all.dropped_pairs(), 0u);
  params.max_cell_share = 0.05;
  const detail::PairFeatureModel capped(plane, params);
  EXPECT_GT(capped.dropped_pairs(), all.pairs() / 2);
  EXPECT_EQ(capped.pairs() + capped.dropped_pairs(), all.pairs());
}

TEST(PointPairVoting, BadParametersThrow) {
  const PointCloud model = bunny_points();
  detail::PairVotingParams params;
  params.step_m = 0;
  EXPECT_THROW(detail::PairFeatureModel(model, params), Error);
  params = {};
  params.alpha_bins = 2;
  EXPECT_THROW(detail::PairFeatureModel(model, params), Error);
  params.alpha_bins = 5000;  // rotations are held in 65536ths of a turn
  EXPECT_THROW(detail::PairFeatureModel(model, params), Error);
  params = {};
  params.angle_bins = 256;  // a bin is one byte in the cosine table
  EXPECT_THROW(detail::PairFeatureModel(model, params), Error);
  params = {};
  params.cluster_distance_factor = 0;  // the clusters are looked for in cubes of this size
  EXPECT_THROW(detail::PairFeatureModel(model, params), Error);
  params = {};
  params.cluster_angle_deg = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(detail::PairFeatureModel(model, params), Error);
  // More than 65536 points at the step: refused before the table of every pair (90,000 squared
  // cells) is allocated.
  PointCloud dense;
  for (int i = 0; i < 300; ++i)
    for (int j = 0; j < 300; ++j) dense.points.emplace_back(0.001f * i, 0.001f * j, 0), dense.normals.emplace_back(0, 0, 1);
  params = {};
  params.step_m = 0.0005;
  EXPECT_THROW(detail::PairFeatureModel(dense, params), Error);
  PointCloud no_normals;
  no_normals.points = model.points;
  EXPECT_THROW(detail::PairFeatureModel(no_normals, {}), Error);
  const detail::PairFeatureModel table(model, {});
  EXPECT_THROW(table.vote(no_normals, {}), Error);
}

}  // namespace
}  // namespace artisan
