// `artisan robot set / show` through the real executable: a UR5 put into a workcell folder (its
// URDF and meshes copied into the workspace), moved joint by joint as versions with their
// authors, shown, listed, exported with the scene; bad input (unknown joint, NaN, a malformed
// NAME=VALUE, a missing URDF, no pose) exits 1 naming what is wrong and changes nothing.
// (`artisan teleop check --joints` needs the service: tests/teleop/test_artisand.cpp.)
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "artisan/worldmodel/robot_store.hpp"
#include "test_support.hpp"
#include "worldmodel/world_fixture.hpp"

namespace artisan {
namespace {

using nlohmann::json;

std::string q(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

class RobotCli : public ::testing::Test {
 protected:
  test::TempDir dir;
  std::string cli;
  test::WorldFixture f;
  void SetUp() override {
    auto ws = worldmodel::Workspace::create(dir / "ws.db");
    f = test::make_world_fixture(ws);
    cli = std::string(ARTISAN_CLI) + " --db " + q(dir / "ws.db") + " ";
  }
  size_t versions() const {
    auto ws = worldmodel::Workspace::open(dir / "ws.db");
    const auto robots = worldmodel::find_robots(ws, "/cell");
    return robots.empty() ? 0 : ws.versions(robots.front().id).size();
  }
};

TEST_F(RobotCli, SetMovesAndShowsARobot) {
  const std::string set = cli + "--json robot set /cell --urdf " + q(test::ur5_urdf()) + " --package-path " + q(test::robot_packages()) +
                          " --pose '0.62 0.3 0.8 0 0 0.70710678 0.70710678' --joint shoulder_lift_joint=-1.9 elbow_joint=1.6 --author alice";
  auto r = test::run_command(set);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = json::parse(r.out);
  EXPECT_EQ(j["path"], "/cell/ur5");
  EXPECT_EQ(j["version"], 1);
  EXPECT_EQ(j["joints"]["shoulder_lift_joint"], -1.9);
  EXPECT_EQ(j["joints"]["wrist_1_joint"], 0.0);
  EXPECT_EQ(j["edit"]["author"], "alice");
  EXPECT_NEAR(j["T_world_root"][3].get<double>(), 0.62, 1e-12);
  EXPECT_EQ(j["joint_names"].size(), 6u);

  r = test::run_command(cli + "--json robot set /cell --joint wrist_1_joint=-1.2 --author bob");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = json::parse(r.out);
  EXPECT_EQ(j["version"], 2);
  EXPECT_EQ(j["joints"]["wrist_1_joint"], -1.2);
  EXPECT_EQ(j["joints"]["elbow_joint"], 1.6);  // kept
  EXPECT_EQ(j["edit"]["author"], "bob");

  r = test::run_command(cli + "--json robot show /cell");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = json::parse(r.out);
  ASSERT_EQ(j.size(), 1u);
  EXPECT_EQ(j[0]["joints"]["wrist_1_joint"], -1.2);
  EXPECT_TRUE(j[0]["T_world_links"].contains("tool0"));
  r = test::run_command(cli + "robot show /cell");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("wrist_1_joint"), std::string::npos) << r.out;
  r = test::run_command(cli + "ls /cell");
  EXPECT_NE(r.out.find("robot 'ur5', 6 joints"), std::string::npos) << r.out;
  r = test::run_command(cli + "--json show /cell/ur5@1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json::parse(r.out)["kind"], "robot");
  // In the exported scene.
  r = test::run_command(cli + "export-scene /cell --format urdf --out " + q(dir / "urdf"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "urdf" / "meshes" / "ur5_wrist_1_link.stl"));
  EXPECT_EQ(test::run_command(cli + "check").exit_code, 0);
}

TEST_F(RobotCli, BadInputExitsOneNamingWhatIsWrong) {
  const std::string base = cli + "robot set /cell --urdf " + q(test::ur5_urdf()) + " --package-path " + q(test::robot_packages()) +
                           " --pose '0 0 0 0 0 0 1' ";
  const auto fails = [&](const std::string& args, const std::string& said) {
    const auto r = test::run_command(args);
    EXPECT_EQ(r.exit_code, 1) << args;
    EXPECT_NE(r.err.find(said), std::string::npos) << args << "\n" << r.err;
  };
  fails(base + "--joint elbow=1", "'elbow'");
  fails(base + "--joint elbow_joint=nan", "not finite");
  fails(base + "--joint elbow_joint", "NAME=VALUE");
  fails(base + "--joint elbow_joint=1.0x", "NAME=VALUE");
  fails(base + "--joint elbow_joint=7", "limits");
  fails(cli + "robot set /cell --urdf " + q(dir / "no.urdf") + " --pose '0 0 0 0 0 0 1'", "no.urdf");
  fails(cli + "robot set /cell --urdf " + q(test::ur5_urdf()) + " --pose '0 0 0 0 0 0 1'", "package://");
  fails(cli + "robot set /cell --urdf " + q(test::ur5_urdf()) + " --package-path " + q(test::robot_packages()), "pose");
  fails(cli + "robot set /cell --joint elbow_joint=1", "--urdf");
  fails(cli + "robot set /nowhere --urdf " + q(test::ur5_urdf()), "/nowhere");
  fails(cli + "robot show /cell --name ur10", "ur10");
  EXPECT_EQ(versions(), 0u);
  // A good one, then a bad change: still one version.
  ASSERT_EQ(test::run_command(base).exit_code, 0);
  fails(cli + "robot set /cell --joint shoulder_pan_joint=inf", "not finite");
  EXPECT_EQ(versions(), 1u);
}

}  // namespace
}  // namespace artisan
