// Scene export: URDF read back by urdfdom, glTF read back by assimp, SDF checked by its poses.
#include <gtest/gtest.h>
#include <urdf_parser/urdf_parser.h>

#include <fstream>
#include <sstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_io.hpp"
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

}  // namespace
}  // namespace artisan::worldmodel
