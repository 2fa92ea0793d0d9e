// Scene export: URDF read back by urdfdom, glTF read back by assimp, SDF checked by its poses; a
// robot in the URDF read back as a robot whose kinematics and collision geometry match the stored
// one.
#include <gtest/gtest.h>
#include <urdf_parser/urdf_parser.h>

#include <fstream>
#include <random>
#include <sstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_io.hpp"
#include "artisan/worldmodel/robot_model.hpp"
#include "artisan/worldmodel/robot_store.hpp"
#include "artisan/worldmodel/scene_export.hpp"
#include "world_fixture.hpp"

namespace artisan::worldmodel {
namespace {

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

class SceneExportTest : public ::testing::Test {
 protected:
  test::TempDir dir;
  Workspace ws = Workspace::create(dir / "ws.db");
  test::WorldFixture f = test::make_world_fixture(ws);
  // A rotated pose so that the orientation is tested too.
  Transform T = Transform(Eigen::Translation3d(0.2, -0.1, 0.05)) * Eigen::AngleAxisd(0.8, Eigen::Vector3d(0.3, -0.5, 1).normalized());
  void SetUp() override {
    WorldModel wm(ws, "/cell");
    wm.correct_pose(f.bunny, T, "test");
  }
};

TEST_F(SceneExportTest, UrdfRoundTripsThroughUrdfdom) {
  WorldModel wm(ws, "/cell");
  const auto files = export_scene(wm, SceneFormat::urdf, dir / "urdf");
  ASSERT_EQ(files.size(), 3u);
  const auto model = urdf::parseURDF(slurp(dir / "urdf" / "scene.urdf"));
  ASSERT_TRUE(model);
  EXPECT_TRUE(model->getLink("environment"));
  const auto joint = model->getJoint("world_to_bunny_in_merged_1");
  ASSERT_TRUE(joint);
  const auto& p = joint->parent_to_joint_origin_transform;
  EXPECT_NEAR(p.position.x, 0.2, 1e-7);
  EXPECT_NEAR(p.position.y, -0.1, 1e-7);
  EXPECT_NEAR(p.position.z, 0.05, 1e-7);
  double x, y, z, w;
  p.rotation.getQuaternion(x, y, z, w);
  const Eigen::Quaterniond q(w, x, y, z), truth(T.rotation());
  EXPECT_LT(q.angularDistance(truth), 1e-6);
  // The mesh it names is there and is the bunny.
  const auto link = model->getLink("bunny_in_merged_1");
  const auto* mesh = dynamic_cast<const urdf::Mesh*>(link->collision->geometry.get());
  ASSERT_NE(mesh, nullptr);
  const auto read = io::read_mesh(dir / "urdf" / mesh->filename);
  EXPECT_EQ(read.faces.size(), f.bunny_mesh.faces.size());
}

TEST_F(SceneExportTest, GltfRoundTripsThroughAssimp) {
  WorldModel wm(ws, "/cell");
  export_scene(wm, SceneFormat::gltf, dir / "gltf");
  const auto read = io::read_mesh(dir / "gltf" / "scene.gltf");  // nodes placed by their transforms
  size_t faces = 0;
  for (const auto& o : wm.objects()) faces += o.mesh->faces.size();
  EXPECT_EQ(read.faces.size(), faces);
  // Bunny vertices are where the pose puts them.
  for (size_t i : {size_t(0), f.bunny_mesh.vertices.size() / 2, f.bunny_mesh.vertices.size() - 1}) {
    const Eigen::Vector3f p = (T * f.bunny_mesh.vertices[i].cast<double>()).cast<float>();
    float best = 1e9f;
    for (const auto& v : read.vertices) best = std::min(best, (v - p).norm());
    EXPECT_LT(best, 1e-5f) << i;
  }
}

TEST_F(SceneExportTest, SdfHasEveryModelAtItsPose) {
  WorldModel wm(ws, "/cell");
  export_scene(wm, SceneFormat::sdf, dir / "sdf");
  const auto text = slurp(dir / "sdf" / "scene.sdf");
  EXPECT_NE(text.find("<model name=\"environment\">"), std::string::npos);
  EXPECT_NE(text.find("<model name=\"bunny_in_merged_1\">"), std::string::npos);
  EXPECT_NE(text.find("<pose>0.2 -0.1 0.05 "), std::string::npos) << text;
  EXPECT_TRUE(std::filesystem::exists(dir / "sdf" / "meshes" / "bunny_in_merged_1.stl"));
  EXPECT_THROW(scene_format_from_string("vrml"), Error);
}

TEST_F(SceneExportTest, CommandLine) {
  const std::string cli = std::string(ARTISAN_CLI) + " --db " + (dir / "ws.db").string() + " ";
  auto r = test::run_command(cli + "export-scene /cell --format urdf --out " + (dir / "cli").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(urdf::parseURDF(slurp(dir / "cli" / "scene.urdf")));
  r = test::run_command(cli + "export-scene /nowhere --out " + (dir / "bad").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("/nowhere"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "bad"));
  EXPECT_EQ(test::run_command(cli + "export-scene /cell --format vrml --out " + (dir / "bad").string()).exit_code, 2);
}

// Method: the exported scene.urdf, loaded as a robot (RobotModel, meshes found relative to the
// file), puts every link of the UR5 where the stored robot puts it, at random joint values within
// limits (the scene's "world" is its root), and its collision hulls have the same vertices up to
// the STL's float precision.
TEST_F(SceneExportTest, TheRobotIsInTheUrdfWithItsKinematics) {
  const Transform T_world_root = parse_transform("0.62 0.3 0.8 0 0 0.70710678 0.70710678");
  RobotSetRequest set;
  set.folder = "/cell";
  set.urdf = test::ur5_urdf();
  set.package_paths = {test::robot_packages()};
  set.T_world_root = T_world_root;
  set.joints = {{"elbow_joint", 1.0}};
  set.author = "test";
  set_robot(ws, set);
  WorldModel wm(ws, "/cell");
  export_scene(wm, SceneFormat::urdf, dir / "urdf");
  const auto text = slurp(dir / "urdf" / "scene.urdf");
  EXPECT_NE(text.find("elbow_joint=1"), std::string::npos);  // the current joints, as a comment
  const auto exported = RobotModel::load(dir / "urdf" / "scene.urdf");
  const auto& stored = *wm.robot().model;
  std::mt19937 rng(3);
  for (int trial = 0; trial < 5; ++trial) {
    std::map<std::string, double> q, q_exported;
    for (const auto& j : stored.joints())
      if (j.movable()) {
        q[j.name] = std::uniform_real_distribution<double>(std::max(j.lower, -3.0), std::min(j.upper, 3.0))(rng);
        q_exported["ur5_" + j.name] = q[j.name];
      }
    const auto truth = stored.link_poses(q, T_world_root);
    const auto mine = exported.link_poses(q_exported, Transform::Identity());
    for (const auto& [link, T_world_link] : truth) {
      ASSERT_TRUE(mine.count("ur5_" + link)) << link;
      EXPECT_TRUE(mine.at("ur5_" + link).isApprox(T_world_link, 1e-7)) << link;  // rpy and 9 digits in the XML
    }
  }
  const auto a = stored.collision_shapes({}, T_world_root);
  std::vector<QueryShape> b;  // the robot's links (the scene's environment and objects are links too)
  for (auto& x : exported.collision_shapes({}, Transform::Identity()))
    if (x.name.find("/ur5_") != std::string::npos) b.push_back(std::move(x));
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ("ur5_" + a[k].name.substr(4), b[k].name.substr(b[k].name.find('/') + 1));
    EXPECT_EQ(a[k].points.size(), b[k].points.size()) << a[k].name;
  }
  // SDF and glTF carry it too.
  export_scene(wm, SceneFormat::sdf, dir / "sdf");
  const auto sdf = slurp(dir / "sdf" / "scene.sdf");
  EXPECT_NE(sdf.find("<model name=\"ur5\">"), std::string::npos);
  EXPECT_NE(sdf.find("<joint name=\"elbow_joint\" type=\"revolute\">"), std::string::npos);
  export_scene(wm, SceneFormat::gltf, dir / "gltf");
  size_t faces = 0;
  for (const auto& o : wm.objects()) faces += o.mesh->faces.size();
  for (const auto& [link, mesh] : stored.link_meshes()) faces += mesh->faces.size();
  EXPECT_EQ(io::read_mesh(dir / "gltf" / "scene.gltf").faces.size(), faces);
}

}  // namespace
}  // namespace artisan::worldmodel
