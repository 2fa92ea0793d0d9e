// MultiMesh assembly against the bunny ground truth (bun.conf): all ten scans added one by one
// with no prior pose; ICP from a rough pose; manual placement; a weak match refused.
#include <gtest/gtest.h>

#include <numbers>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/stanford_conf.hpp"
#include "artisan/worldmodel/multimesh.hpp"
#include "artisan/worldmodel/operations.hpp"
#include "test_support.hpp"

namespace artisan::worldmodel {
namespace {

class MultiMeshTest : public ::testing::Test {
 protected:
  void SetUp() override {
    folder_ = ws_.mkdir("/bunny");
    for (const auto& name : test::bunny_scans()) {
      const auto path = test::bunny_dir() / (name + ".ply");
      const auto image = ws_.add(folder_, make_image_object(name, io::ply_to_range_image(io::read_ply(path), path), {"import", {}, {}}));
      mesh_[name] = run_operation(ws_, "mesh", {image}, nlohmann::json::object(), folder_, name + "-mesh");
    }
  }
  Transform truth_root_member(const std::string& root, const std::string& member) const {
    return conf_.scan(root + ".ply").T_world_scan.inverse() * conf_.scan(member + ".ply").T_world_scan;
  }
  static void expect_near(const Transform& estimate, const Transform& truth, double max_deg, double max_mm, const std::string& what) {
    const Transform d = truth.inverse() * estimate;
    EXPECT_LT(rotation_angle(d) * 180 / std::numbers::pi, max_deg) << what;
    EXPECT_LT(d.translation().norm() * 1e3, max_mm) << what;
  }

  test::TempDir dir_;
  Workspace ws_ = Workspace::create(dir_ / "ws.db");
  ObjectId folder_ = 0;
  std::map<std::string, ObjectId> mesh_;
  io::StanfordConf conf_ = io::read_stanford_conf(test::bunny_dir() / "bun.conf");
};

TEST_F(MultiMeshTest, AllTenScansAddedOneByOneLandWithin2DegreesAnd2mm) {
  const auto mm = create_multimesh(ws_, folder_, "views");
  int loops = 0;
  for (const auto& name : test::bunny_scans()) {
    const auto report = add_to_multimesh(ws_, mm, {mesh_[name], std::nullopt, "auto", std::nullopt, true});
    loops += !report.loop_closure.is_null();
  }
  EXPECT_GT(loops, 0);  // the bunny's views close loops
  const auto members = ws_.members(mm);
  ASSERT_EQ(members.size(), 10u);
  const auto T_root = root_transforms(members);
  for (const auto& m : members) {
    const auto name = ws_.get(m.mesh).name.substr(0, ws_.get(m.mesh).name.size() - 5);  // strip "-mesh"
    expect_near(T_root.at(m.member_id), truth_root_member("bun000", name), 2.0, 2.0, name);
  }
  EXPECT_TRUE(ws_.check().problems.empty());
  // A mesh cannot join twice; the mesh in a multimesh cannot be removed alone.
  EXPECT_THROW(add_to_multimesh(ws_, mm, {mesh_["bun045"], std::nullopt, "auto", std::nullopt, true}), Error);
  EXPECT_THROW(ws_.remove(mesh_["bun045"], false), Error);
}

TEST_F(MultiMeshTest, IcpFromARoughPoseAndManualPlacement) {
  const auto mm = create_multimesh(ws_, folder_, "manual");
  add_to_multimesh(ws_, mm, {mesh_["bun000"], std::nullopt, "auto", std::nullopt, true});
  // bun045 from the truth perturbed by 4 degrees and 5 mm: ICP must pull it in.
  Transform rough = truth_root_member("bun000", "bun045");
  rough = rough * Transform(Eigen::AngleAxisd(4.0 * std::numbers::pi / 180, Eigen::Vector3d::UnitY()));
  rough.translation() += Eigen::Vector3d(0.005, 0, 0);
  const auto icp = add_to_multimesh(ws_, mm, {mesh_["bun045"], mesh_["bun000"], "icp", rough, true});
  expect_near(icp.T_parent_member, truth_root_member("bun000", "bun045"), 0.5, 1.0, "icp");
  // Manual without refinement stores the pose exactly as given.
  const auto manual = add_to_multimesh(ws_, mm, {mesh_["bun315"], mesh_["bun000"], "manual", rough, false});
  EXPECT_TRUE(manual.T_parent_member.isApprox(rough));
  EXPECT_EQ(manual.quality["refined"], false);
  // icp without --init is refused.
  EXPECT_THROW(add_to_multimesh(ws_, mm, {mesh_["chin"], mesh_["bun000"], "icp", std::nullopt, true}), Error);
}

TEST_F(MultiMeshTest, AWeakMatchIsRefusedWithItsFiguresAndNothingStored) {
  // Method: bun180 sees the back of the bunny, bun000 the front; they barely overlap.
  const auto mm = create_multimesh(ws_, folder_, "weak");
  add_to_multimesh(ws_, mm, {mesh_["bun000"], std::nullopt, "auto", std::nullopt, true});
  try {
    add_to_multimesh(ws_, mm, {mesh_["bun180"], std::nullopt, "auto", std::nullopt, true});
    FAIL() << "bun180 was accepted against bun000 alone";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("too weak"), std::string::npos) << e.what();
  }
  EXPECT_EQ(ws_.members(mm).size(), 1u);
}

}  // namespace
}  // namespace artisan::worldmodel
