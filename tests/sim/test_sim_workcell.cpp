// Workcell loading (the sample pipework cell, URDF robots, pan/tilt limits), physics settling,
// bad input.
#include <gtest/gtest.h>

#include <fstream>

#include "artisan/core/error.hpp"
#include "artisan/sim/physics.hpp"
#include "artisan/sim/workcell.hpp"
#include "test_support.hpp"

namespace artisan::sim {
namespace {

const auto kPipework = artisan::test::data_dir() / "workcells" / "pipework.json";

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

// Method: the sample cell loads with its structure, objects, two URDF robots (UR5: 6 revolute
// joints; PTU-D46: pan/tilt with the limits of its description) and three sensors.
TEST(SimWorkcell, SampleLoads) {
  const auto cell = load_workcell(kPipework);
  int objects = 0, links = 0;
  for (const auto& b : cell.bodies) {
    objects += b.role == BodyRole::object;
    links += b.role == BodyRole::robot_link;
    EXPECT_FALSE(b.mesh.faces.empty()) << b.name;
  }
  EXPECT_GE(objects, 8);
  EXPECT_GE(links, 7);
  ASSERT_EQ(cell.sensors.size(), 3u);
  const auto& ptu = cell.robot("ptu");
  EXPECT_NEAR(ptu.joint("ptu_pan").upper, 2.775, 1e-9);
  EXPECT_NEAR(ptu.joint("ptu_tilt").lower, -0.82, 1e-9);
  EXPECT_NEAR(ptu.joint("ptu_tilt").velocity, 1.0, 1e-9);
  int revolute = 0;
  for (const auto& j : cell.robot("ur5").joints) revolute += j.type == JointSpec::Type::revolute;
  EXPECT_EQ(revolute, 6);
}

// Method: forward kinematics of the PTU-D46 description by hand: pan turns about the base z
// axis; the mount sits 0.046774 + 0.043713 + 0.039116 m above the base (URDF joint origins),
// independent of pan.
TEST(SimWorkcell, PanTiltKinematics) {
  auto cell = load_workcell(kPipework);
  cell.set_joint("ptu", "ptu_pan", 0.0);
  cell.set_joint("ptu", "ptu_tilt", 0.0);
  const Transform T0 = cell.robot("ptu").link_poses().at("ptu_mount_link");
  cell.set_joint("ptu", "ptu_pan", 0.5);
  const Transform T1 = cell.robot("ptu").link_poses().at("ptu_mount_link");
  const Transform T_root = cell.robot("ptu").T_world_root;
  const Transform rel = (T_root.inverse() * T0).inverse() * (T_root.inverse() * T1);
  EXPECT_NEAR(rotation_angle(rel), 0.5, 1e-6);
  const Eigen::Vector3d p0 = T_root.inverse() * T0.translation();
  EXPECT_NEAR(p0.z(), 0.046774 + 0.043713 + 0.039116, 1e-3);
  const Eigen::Vector3d axis = (T_root.inverse().linear() * T0.linear()) * Eigen::AngleAxisd(rel.linear()).axis();
  EXPECT_NEAR(std::abs(axis.z()), 1.0, 1e-6);
}

// Method: bad input names the file, the field and the value.
TEST(SimWorkcell, BadInputThrowsWithContext) {
  artisan::test::TempDir dir;
  auto write = [&](const std::string& text) {
    std::ofstream(dir / "w.json") << text;
    return dir / "w.json";
  };
  EXPECT_NE(error_of([&] { load_workcell(write("{ not json")); }).find("not valid JSON"), std::string::npos);
  EXPECT_NE(error_of([&] { load_workcell(write(R"({"structure": [{"name": "a", "mesh": "missing.stl"}]})")); }).find("missing.stl"),
            std::string::npos);
  EXPECT_NE(error_of([&] { load_workcell(write(R"({"structure": [{"name": "a", "primitive": {"box": [1, -1, 1]}}]})")); })
                .find("structure[0].primitive.box"),
            std::string::npos);
  EXPECT_NE(error_of([&] { load_workcell(write(R"({"sensors": [{"name": "s", "kind": "kinect"}]})")); }).find("kinect"),
            std::string::npos);
  EXPECT_NE(error_of([&] { load_workcell(write(R"({"objects": [{"name": "a", "primitive": {"sphere": 1}, "colour": 1}]})")); })
                .find("objects[0].colour"),
            std::string::npos);
  auto cell = load_workcell(kPipework);
  EXPECT_NE(error_of([&] { cell.sensor("kinect"); }).find("vivid, pioneer"), std::string::npos);
  const auto msg = error_of([&] { cell.set_joint("ptu", "ptu_tilt", 0.9); });
  EXPECT_NE(msg.find("0.9"), std::string::npos) << msg;
  EXPECT_NE(msg.find("0.52"), std::string::npos) << msg;
}

double table_top() { return 0.8; }

// Method: the sample's dropped objects fall from 13-20 cm above the table and are settled by
// Bullet. Every one must come to rest within the time limit, with its lowest exact-mesh vertex
// on the table top (no lower than 2 mm into it, no higher than 4 mm above it: collision margin
// and convex hulls), inside the table's outline, and no two collision shapes may overlap by
// more than 3 mm. Settling twice gives identical poses (determinism).
TEST(SimPhysics, SampleObjectsSettleOnTheTable) {
  auto cell = load_workcell(kPipework);
  auto again = load_workcell(kPipework);
  const auto r = settle(cell);
  settle(again);
  std::printf("settled %d objects in %.2f s simulated (%d steps), at rest: %d\n", r.dropped, r.simulated_time_s, r.steps, r.at_rest);
  EXPECT_TRUE(r.at_rest);
  EXPECT_GE(r.dropped, 8);
  for (size_t i = 0; i < cell.bodies.size(); ++i) {
    const auto& b = cell.bodies[i];
    if (!b.drop) continue;
    double zmin = 1e9;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const auto& v : b.mesh.vertices) {
      const Eigen::Vector3d p = b.T_world_body * v.cast<double>();
      zmin = std::min(zmin, p.z());
      centre += p;
    }
    centre /= static_cast<double>(b.mesh.vertices.size());
    std::printf("  %-10s lowest point %.4f m (table %.3f)\n", b.name.c_str(), zmin, table_top());
    EXPECT_GT(zmin, table_top() - 0.002) << b.name;
    EXPECT_LT(zmin, table_top() + 0.004) << b.name;
    EXPECT_LT(std::abs(centre.x()), 0.8) << b.name;
    EXPECT_LT(std::abs(centre.y()), 0.45) << b.name;
    EXPECT_TRUE(b.T_world_body.isApprox(again.bodies[i].T_world_body, 0)) << b.name;
  }
  const auto contacts = check_contacts(cell);
  std::printf("deepest overlap %.4f m (%s)\n", contacts.max_penetration_m, contacts.deepest_pair.c_str());
  EXPECT_LT(contacts.max_penetration_m, 0.003) << contacts.deepest_pair;
}

// Method: the check itself must see an interpenetration when one is made: push one settled
// object 2 cm down into the table.
TEST(SimPhysics, ContactCheckSeesInterpenetration) {
  auto cell = load_workcell(kPipework);
  settle(cell);
  for (auto& b : cell.bodies)
    if (b.name == "toolbox") b.T_world_body.translation().z() -= 0.02;
  EXPECT_GT(check_contacts(cell).max_penetration_m, 0.015);
}

}  // namespace
}  // namespace artisan::sim
