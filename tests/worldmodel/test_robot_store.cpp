// Robots in the workspace: a robot object keeps the URDF and its meshes (the workspace needs no
// outside file afterwards), pose and joint values, each change a new version with author and
// time; bad input is refused and stores nothing; a version-2 workspace migrates to version 3
// (the objects table rebuilt) keeping every row, ID, blob and reference.
#include <gtest/gtest.h>

#include <fstream>

#include "../../worldmodel/src/schema.hpp"  // the released schema scripts, to build a version-2 workspace
#include "artisan/core/error.hpp"
#include "artisan/worldmodel/robot_store.hpp"
#include "test_support.hpp"

namespace artisan::worldmodel {
namespace {

namespace fs = std::filesystem;
const auto kUrdf = test::data_dir() / "robots/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf";
const Transform kPipeworkPose = parse_transform("0.62 0.3 0.8 0 0 0.70710678 0.70710678");  // data/workcells/pipework.json

RobotSetRequest ur5_request(const fs::path& urdf = kUrdf, const std::vector<fs::path>& packages = {test::data_dir() / "robots"}) {
  RobotSetRequest r;
  r.folder = "/cell";
  r.urdf = urdf;
  r.package_paths = packages;
  r.T_world_root = kPipeworkPose;
  r.joints = {{"shoulder_pan_joint", 0.4}, {"shoulder_lift_joint", -1.9}, {"elbow_joint", 1.6}};
  r.author = "alice";
  return r;
}

// Method: the robot is stored from a copy of the description (URDF and meshes copied into a
// temporary package folder), the copy is deleted, and the stored robot's link poses and
// collision shapes equal those of RobotModel::load() on the original files.
TEST(RobotStore, KeepsItsOwnCopyAndEveryChangeAsAVersion) {
  test::TempDir dir;
  auto ws = Workspace::create(dir / "ws.db");
  ws.mkdir("/cell");
  const fs::path package = dir / "package";
  fs::create_directories(package / "example-robot-data/robots");
  fs::copy(test::data_dir() / "robots/example-robot-data/robots/ur_description", package / "example-robot-data/robots/ur_description",
           fs::copy_options::recursive);
  const ObjectId v1 = set_robot(ws, ur5_request(package / "example-robot-data/robots/ur_description/urdf/ur5_robot.urdf", {package}));
  fs::remove_all(package);

  const auto info = ws.get(v1);
  EXPECT_EQ(info.kind, ObjectKind::kRobot);
  EXPECT_EQ(info.name, "ur5");
  EXPECT_EQ(info.subkind, "ur5");
  EXPECT_EQ(info.path, "/cell/ur5");
  EXPECT_EQ(info.metadata["edit"]["author"], "alice");
  EXPECT_EQ(info.metadata["edit"]["action"], "create");
  EXPECT_EQ(info.metadata["meshes"].size(), 7u);  // the collision meshes of the seven links
  EXPECT_EQ(ws.blobs(v1).size(), 8u);             // with the URDF
  const auto stored = load_robot(ws, v1);
  const auto original = RobotModel::load(kUrdf, {test::data_dir() / "robots"});
  EXPECT_EQ(stored.model->joint_names(), original.joint_names());
  EXPECT_EQ(stored.joints.at("shoulder_lift_joint"), -1.9);
  EXPECT_EQ(stored.joints.at("wrist_1_joint"), 0.0);  // not given: its default
  EXPECT_TRUE(stored.T_world_root.isApprox(kPipeworkPose, 1e-12));
  const auto mine = stored.model->link_poses(stored.joints, stored.T_world_root);
  const auto theirs = original.link_poses(stored.joints, kPipeworkPose);
  ASSERT_EQ(mine.size(), theirs.size());
  for (const auto& [link, T] : theirs) EXPECT_TRUE(mine.at(link).isApprox(T, 1e-12)) << link;
  const auto shapes = stored.model->collision_shapes(stored.joints, stored.T_world_root);
  const auto original_shapes = original.collision_shapes(stored.joints, kPipeworkPose);
  ASSERT_EQ(shapes.size(), original_shapes.size());
  for (size_t k = 0; k < shapes.size(); ++k) {
    EXPECT_EQ(shapes[k].name, original_shapes[k].name);
    EXPECT_EQ(shapes[k].points, original_shapes[k].points);
  }

  // Moving one joint: version 2 by bob, the other joints kept, the data carried over.
  RobotSetRequest move;
  move.folder = "/cell";
  move.joints = {{"wrist_1_joint", -1.2}};
  move.author = "bob";
  const ObjectId v2 = set_robot(ws, move);
  const auto second = ws.get(v2);
  EXPECT_EQ(second.version, 2);
  EXPECT_EQ(second.metadata["edit"]["author"], "bob");
  EXPECT_EQ(second.metadata["edit"]["action"], "set");
  EXPECT_EQ(ws.provenance(v2)->inputs, std::vector<ObjectId>{v1});
  const auto moved = load_robot(ws, v2);
  EXPECT_EQ(moved.joints.at("wrist_1_joint"), -1.2);
  EXPECT_EQ(moved.joints.at("shoulder_lift_joint"), -1.9);
  EXPECT_TRUE(moved.T_world_root.isApprox(kPipeworkPose, 1e-12));
  EXPECT_EQ(ws.blobs(v2).size(), 8u);
  EXPECT_EQ(load_robot(ws, v1).joints.at("wrist_1_joint"), 0.0);  // version 1 as it was
  EXPECT_EQ(find_robots(ws, "/").size(), 1u);
  EXPECT_TRUE(ws.check().problems.empty());
}

TEST(RobotStore, BadInputIsRefusedAndStoresNothing) {
  test::TempDir dir;
  auto ws = Workspace::create(dir / "ws.db");
  ws.mkdir("/cell");
  auto r = ur5_request();
  r.urdf = dir / "missing.urdf";
  EXPECT_NE(test::error_of([&] { set_robot(ws, r); }).find("missing.urdf"), std::string::npos);
  r = ur5_request(kUrdf, {});
  EXPECT_NE(test::error_of([&] { set_robot(ws, r); }).find("package://example-robot-data"), std::string::npos);
  r = ur5_request();
  r.joints = {{"elbow", 1.0}};
  const auto unknown = test::error_of([&] { set_robot(ws, r); });
  EXPECT_NE(unknown.find("'elbow'"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("elbow_joint"), std::string::npos) << unknown;  // lists the joints there are
  r.joints = {{"elbow_joint", NAN}};
  EXPECT_NE(test::error_of([&] { set_robot(ws, r); }).find("elbow_joint"), std::string::npos);
  r.joints = {{"elbow_joint", 4.0}};
  EXPECT_NE(test::error_of([&] { set_robot(ws, r); }).find("limits"), std::string::npos);
  r = ur5_request();
  r.T_world_root.reset();
  EXPECT_NE(test::error_of([&] { set_robot(ws, r); }).find("pose"), std::string::npos);
  r = ur5_request();
  r.author = "";
  EXPECT_NE(test::error_of([&] { set_robot(ws, r); }).find("author"), std::string::npos);
  r = ur5_request();
  r.folder = "/nowhere";
  EXPECT_FALSE(test::error_of([&] { set_robot(ws, r); }).empty());
  RobotSetRequest no_robot;
  no_robot.folder = "/cell";
  no_robot.joints = {{"elbow_joint", 1.0}};
  no_robot.author = "alice";
  EXPECT_NE(test::error_of([&] { set_robot(ws, no_robot); }).find("--urdf"), std::string::npos);
  // A name taken by another kind of object.
  ws.mkdir("/cell/ur5");
  EXPECT_NE(test::error_of([&] { set_robot(ws, ur5_request()); }).find("not a robot"), std::string::npos);
  EXPECT_TRUE(find_robots(ws, "/").empty());
  EXPECT_TRUE(ws.check().problems.empty());
}

// Method: a workspace made with the released version-1 and version-2 schema scripts, as an older
// build left it (folders, a mesh with its blob and provenance, a multimesh member, a grid block,
// a version chain, and the newest row deleted so the AUTOINCREMENT counter is above every ID),
// opens as version 3 with every row, blob and reference intact, and new IDs stay above the
// counter.
TEST(RobotStore, VersionTwoWorkspaceMigrates) {
  test::TempDir dir;
  const auto path = dir / "v2.db";
  {
    auto db = open_sqlite(path, {.create = true});
    db->execute_script(detail::migrations().at(0));
    db->execute_script(detail::migrations().at(1));
    db->query("INSERT INTO meta (key, value) VALUES ('schema_version', '2')");
    db->execute_script(R"sql(
INSERT INTO objects (id, kind, name, created_at) VALUES (1, 'folder', '', '2026-01-01T00:00:00.000Z');
INSERT INTO objects (id, kind, folder_id, name, created_at) VALUES (2, 'folder', 1, 'cell', '2026-01-01T00:00:00.000Z');
INSERT INTO objects (id, kind, subkind, folder_id, name, created_at, metadata) VALUES (3, 'mesh', 'original', 2, 'm', '2026-01-01T00:00:00.000Z', '{"faces": 1}');
INSERT INTO objects (id, kind, subkind, folder_id, name, version, previous_version_id, created_at) VALUES (4, 'mesh', 'original', 2, 'm', 2, 3, '2026-01-02T00:00:00.000Z');
INSERT INTO objects (id, kind, folder_id, name, created_at) VALUES (5, 'multimesh', 2, 'views', '2026-01-01T00:00:00.000Z');
INSERT INTO objects (id, kind, folder_id, name, created_at) VALUES (6, 'grid', 2, 'g', '2026-01-01T00:00:00.000Z');
INSERT INTO objects (id, kind, folder_id, name, created_at) VALUES (7, 'folder', 2, 'gone', '2026-01-01T00:00:00.000Z');
DELETE FROM objects WHERE id = 7;
INSERT INTO blobs (object_id, role, encoding, size, crc32, data) VALUES (3, 'note', 'text', 3, 891568578, X'616263');
INSERT INTO provenance (object_id, operation, parameters, software) VALUES (4, 'reprocess', '{}', 'artisan 0.1.0');
INSERT INTO provenance_inputs (object_id, position, input_id) VALUES (4, 0, 3);
INSERT INTO multimesh_members (multimesh_id, mesh_id, T_parent_member, method) VALUES (5, 4, '[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]', 'root');
INSERT INTO grid_blocks (grid_id, x, y, z, size, crc32, data) VALUES (6, 0, 0, 0, 3, 891568578, X'616263');
)sql");
  }
  auto ws = Workspace::open(path);
  EXPECT_EQ(ws.schema_version(), Workspace::kSchemaVersion);
  EXPECT_EQ(Workspace::kSchemaVersion, 3);
  EXPECT_EQ(ws.resolve("/cell/m").id, 4);
  EXPECT_EQ(ws.resolve("/cell/m@1").metadata["faces"], 1);
  EXPECT_EQ(ws.versions(4).size(), 2u);
  EXPECT_EQ(ws.provenance(4)->inputs, std::vector<ObjectId>{3});
  EXPECT_EQ(ws.blob(3, "note"), (SqlBlob{'a', 'b', 'c'}));
  EXPECT_EQ(ws.members(5).size(), 1u);
  EXPECT_TRUE(ws.grid_block(6, {0, 0, 0}).has_value());
  const auto report = ws.check();
  EXPECT_TRUE(report.problems.empty()) << report.problems.front();
  // The references still hold: removing the mesh is refused (a multimesh holds it), removing the
  // grid takes its blocks with it.
  EXPECT_THROW(ws.remove(3, false), Error);
  ws.remove(6, false);
  EXPECT_FALSE(ws.grid_block(6, {0, 0, 0}).has_value());
  // New rows continue above the deleted one, and the new kind is accepted.
  NewObject f;
  f.kind = ObjectKind::kFolder;
  f.name = "next";
  EXPECT_GT(ws.add(ws.folder("/cell").id, f), 7);
  ObjectId robot = 0;
  EXPECT_NO_THROW(robot = set_robot(ws, ur5_request()));
  EXPECT_EQ(ws.get(robot).kind, ObjectKind::kRobot);
  EXPECT_TRUE(ws.check().problems.empty());
  // Opening it again changes nothing.
  auto again = Workspace::open(path);
  EXPECT_EQ(again.resolve("/cell/ur5").id, robot);
}

}  // namespace
}  // namespace artisan::worldmodel
