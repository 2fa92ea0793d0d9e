// Robot model from URDF: forward kinematics agrees with the simulator's (an independent
// implementation) for random joint values; collision shapes checked against a floor; bad input.
#include <gtest/gtest.h>

#include <random>

#include "artisan/core/error.hpp"
#include "artisan/sim/workcell.hpp"
#include "artisan/worldmodel/robot_model.hpp"
#include "test_support.hpp"

namespace artisan::worldmodel {
namespace {

const auto kUrdf = test::data_dir() / "robots/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf";

TEST(RobotModel, KinematicsAgreeWithTheSimulator) {
  const auto robot = RobotModel::load(kUrdf, {test::data_dir() / "robots"});
  EXPECT_EQ(robot.joint_names().size(), 6u);
  auto cell = sim::load_workcell(test::data_dir() / "workcells/pipework.json");
  auto& ur5 = cell.robot("ur5");
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int trial = 0; trial < 20; ++trial) {
    std::map<std::string, double> q;
    for (const auto& j : robot.joint_names()) q[j] = ur5.joint_values[j] = u(rng);
    const auto mine = robot.link_poses(q, ur5.T_world_root);
    const auto theirs = ur5.link_poses();
    for (const auto& [link, T] : theirs) {
      ASSERT_TRUE(mine.count(link)) << link;
      EXPECT_TRUE(mine.at(link).isApprox(T, 1e-9)) << link;
    }
  }
}

TEST(RobotModel, CollisionShapesMeetAFloor) {
  const auto robot = RobotModel::load(kUrdf, {test::data_dir() / "robots"});
  auto floor = std::make_shared<TriangleMesh>();
  floor->vertices = {{-3, -3, 0}, {3, -3, 0}, {3, 3, 0}, {-3, 3, 0}};
  floor->faces = {{0, 1, 2}, {0, 2, 3}};
  CollisionScene scene;
  scene.set_body(1, floor, Transform::Identity());
  const auto shapes_up = robot.collision_shapes({}, Transform(Eigen::Translation3d(0, 0, 0.05)));
  EXPECT_GE(shapes_up.size(), 7u);
  EXPECT_FALSE(scene.check(shapes_up).in_collision);  // standing 5 cm above the floor, arm out straight
  // The base sunk into the floor collides; the shoulder lifted down past the floor too.
  EXPECT_TRUE(scene.check(robot.collision_shapes({}, Transform(Eigen::Translation3d(0, 0, -0.02)))).in_collision);
  const auto down = robot.collision_shapes({{"shoulder_lift_joint", M_PI / 2}}, Transform(Eigen::Translation3d(0, 0, 0.05)));
  const auto hit = scene.check(down);
  ASSERT_TRUE(hit.in_collision);
  for (const auto& c : hit.contacts) EXPECT_NE(c.shape, "ur5/base_link");
}

TEST(RobotModel, BadInputIsRefused) {
  EXPECT_THROW(RobotModel::load(test::data_dir() / "nowhere.urdf"), Error);
  EXPECT_THROW(RobotModel::load(kUrdf, {}), Error);  // the package:// meshes cannot be found
  const auto robot = RobotModel::load(kUrdf, {test::data_dir() / "robots"});
  EXPECT_THROW(robot.link_poses({{"elbow", 0.0}}, Transform::Identity()), Error);
  EXPECT_THROW(robot.link_poses({{"elbow_joint", NAN}}, Transform::Identity()), Error);
  EXPECT_THROW(robot.link_poses({{"elbow_joint", 100.0}}, Transform::Identity()), Error);
}

}  // namespace
}  // namespace artisan::worldmodel
