// The workspace store through its C++ interface: object tree, paths, blobs, provenance,
// versions, removal rules, moves, integrity check, migrations.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <random>
#include <thread>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/worldmodel/workspace.hpp"
#include "test_support.hpp"

namespace artisan::worldmodel {
namespace {

RangeImage bunny_scan(const std::string& name) {
  const auto path = test::bunny_dir() / (name + ".ply");
  return io::ply_to_range_image(io::read_ply(path), path);
}

TriangleMesh triangle() {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.faces = {{0, 1, 2}};
  return m;
}

class WorkspaceTest : public ::testing::Test {
 protected:
  test::TempDir dir_;
  Workspace ws_ = Workspace::create(dir_ / "ws.db");
};

TEST_F(WorkspaceTest, FoldersAndPathsBehaveLikeAFileExplorer) {
  const auto east = ws_.mkdir("/cell/east");
  EXPECT_EQ(ws_.get(east).path, "/cell/east");
  EXPECT_EQ(ws_.mkdir("/cell/east"), east);  // existing is fine
  EXPECT_EQ(ws_.resolve("/cell").kind, ObjectKind::kFolder);
  EXPECT_EQ(ws_.resolve(std::to_string(east)).id, east);
  EXPECT_EQ(ws_.resolve("/").id, ws_.root());
  EXPECT_EQ(ws_.children(ws_.resolve("/cell").id).size(), 1u);
  for (const std::string bad : {"cell", "/cell/", "//cell", "/cell/../x", "/ce ll", "/cell/east@x"}) {
    EXPECT_THROW(ws_.resolve(bad), Error) << bad;
  }
  EXPECT_THROW(ws_.resolve("/cell/west"), Error);
  EXPECT_THROW(ws_.resolve("999"), Error);
}

TEST_F(WorkspaceTest, A512x400RealScanRoundTripsBitExactly) {
  const auto image = bunny_scan("bun000");
  const auto id = ws_.add(ws_.mkdir("/scans"), make_image_object("bun000", image, {"import", {{"source", "x"}}, {}}));
  EXPECT_TRUE(ws_.load_image(id) == image);
  const auto info = ws_.get(id);
  EXPECT_EQ(info.kind, ObjectKind::kImage);
  EXPECT_EQ(info.subkind, "cyberware");
  EXPECT_EQ(info.metadata["valid_pixels"], 40256);
  EXPECT_EQ(info.metadata["sensor"]["attributes"]["num_cols"], "512");
  // Compressed: smaller than the 850 kB binary PLY.
  EXPECT_LT(ws_.blob(id, "range_image").size(), 500000u);
}

TEST_F(WorkspaceTest, ProvenanceVersionsAndDerivedObjects) {
  const auto folder = ws_.mkdir("/a");
  const auto image = ws_.add(folder, make_image_object("scan", bunny_scan("bun090"), {"import", {}, {}}));
  const Provenance p{"mesh", {{"min_angle_deg", 20.7}}, {image}};
  const auto v1 = ws_.add(folder, make_mesh_object(ObjectKind::kMesh, "original", "scan-mesh", triangle(), p));
  auto p2 = p;
  p2.parameters["min_angle_deg"] = 25.0;
  const auto v2 = ws_.add_version(v1, make_mesh_object(ObjectKind::kMesh, "original", "scan-mesh", triangle(), p2));
  EXPECT_EQ(ws_.get(v2).version, 2);
  EXPECT_EQ(ws_.get(v2).previous_version, v1);
  EXPECT_EQ(ws_.resolve("/a/scan-mesh").id, v2);    // the latest
  EXPECT_EQ(ws_.resolve("/a/scan-mesh@1").id, v1);  // an older one by number
  EXPECT_EQ(ws_.versions(v1).size(), 2u);
  EXPECT_EQ(ws_.children(folder).size(), 2u);  // one entry per object, not per version
  EXPECT_EQ(ws_.provenance(v2)->parameters["min_angle_deg"], 25.0);
  EXPECT_EQ(ws_.provenance(v1)->inputs, std::vector<ObjectId>{image});
  EXPECT_EQ(ws_.derived_from(image).size(), 2u);
}

TEST_F(WorkspaceTest, RemovingAnInputIsRefusedNamingTheDerivedObjects) {
  const auto folder = ws_.mkdir("/a");
  const auto image = ws_.add(folder, make_image_object("scan", bunny_scan("bun090"), {"import", {}, {}}));
  ws_.add(folder, make_mesh_object(ObjectKind::kMesh, "original", "scan-mesh", triangle(), {"mesh", {}, {image}}));
  try {
    ws_.remove(image, false);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("/a/scan-mesh"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ws_.remove(folder, false), Error);  // not empty
  EXPECT_THROW(ws_.remove(ws_.root(), true), Error);
  ws_.remove(image, true);
  EXPECT_TRUE(ws_.children(folder).empty());
  EXPECT_TRUE(ws_.check().problems.empty());
}

TEST_F(WorkspaceTest, MoveRenamesAndRefusesCycles) {
  const auto a = ws_.mkdir("/a");
  const auto b = ws_.mkdir("/b");
  const auto m = ws_.add(a, make_mesh_object(ObjectKind::kMesh, "original", "m", triangle(), {"import", {}, {}}));
  ws_.move(m, "/b");
  EXPECT_EQ(ws_.get(m).path, "/b/m");
  ws_.move(m, "/b/renamed");
  EXPECT_EQ(ws_.get(m).path, "/b/renamed");
  EXPECT_THROW(ws_.move(a, "/a/inner"), Error);   // into itself
  EXPECT_THROW(ws_.move(m, "/nowhere/x"), Error); // no such folder
  ws_.move(a, "/b");
  EXPECT_EQ(ws_.get(a).path, "/b/a");
  EXPECT_EQ(ws_.get(b).path, "/b");
}

TEST_F(WorkspaceTest, DuplicateNamesAndWrongKindsAreRefused) {
  const auto a = ws_.mkdir("/a");
  const auto m = ws_.add(a, make_mesh_object(ObjectKind::kMesh, "original", "m", triangle(), {"import", {}, {}}));
  EXPECT_THROW(ws_.add(a, make_mesh_object(ObjectKind::kMesh, "original", "m", triangle(), {"import", {}, {}})), Error);
  EXPECT_THROW(ws_.add(m, make_mesh_object(ObjectKind::kMesh, "original", "x", triangle(), {"import", {}, {}})), Error);
  EXPECT_THROW(ws_.load_image(m), Error);
  EXPECT_THROW(ws_.add(a, make_mesh_object(ObjectKind::kMesh, "", "bad name", triangle(), {})), Error);
  EXPECT_THROW(ws_.add(a, make_mesh_object(ObjectKind::kMesh, "", "x", triangle(), Provenance{"op", {}, {12345}})), Error);
  EXPECT_EQ(ws_.children(a).size(), 1u);  // the failed adds left nothing
}

TEST_F(WorkspaceTest, MultiMeshMembersKeepTheirTransforms) {
  const auto f = ws_.mkdir("/mm");
  const auto m1 = ws_.add(f, make_mesh_object(ObjectKind::kMesh, "original", "m1", triangle(), {"import", {}, {}}));
  const auto m2 = ws_.add(f, make_mesh_object(ObjectKind::kMesh, "original", "m2", triangle(), {"import", {}, {}}));
  NewObject mm;
  mm.kind = ObjectKind::kMultiMesh;
  mm.name = "views";
  const auto mmid = ws_.add(f, mm);
  const auto root = ws_.add_member(mmid, {0, m1, std::nullopt, Transform::Identity(), "root", {}});
  const auto T = parse_transform("0.1 0 0 0 0 0.7071067811865476 0.7071067811865476");
  ws_.add_member(mmid, {0, m2, root, T, "spin", {{"overlap", 0.6}}});
  const auto members = ws_.members(mmid);
  ASSERT_EQ(members.size(), 2u);
  EXPECT_TRUE(members[1].T_parent_member.isApprox(T, 1e-12));
  EXPECT_EQ(members[1].quality["overlap"], 0.6);
  EXPECT_THROW(ws_.remove(m2, false), Error);  // the multimesh uses it
}

TEST_F(WorkspaceTest, CheckFindsCorruptBlobs) {
  const auto id = ws_.add(ws_.mkdir("/s"), make_image_object("scan", bunny_scan("bun090"), {"import", {}, {}}));
  EXPECT_TRUE(ws_.check().problems.empty());
  auto db = open_sqlite(dir_ / "ws.db");
  db->query("UPDATE blobs SET data = zeroblob(100) WHERE object_id = ?", {id});
  const auto report = Workspace::open(dir_ / "ws.db").check();
  ASSERT_FALSE(report.problems.empty());
  EXPECT_NE(report.problems[0].find("object " + std::to_string(id)), std::string::npos) << report.problems[0];
}

// The service's mode: commits only add to the write-ahead log, and a thread of the database's
// own copies the log into the database file (a checkpoint, with its fsyncs) while the writer
// goes on. Without that thread nothing would reach the database file before the workspace
// closed, since the hook that wakes it replaces SQLite's checkpoint in the commit.
TEST_F(WorkspaceTest, BackgroundMaintenanceCheckpointsTheLogWhileTheWriterGoesOn) {
  ws_.maintain_in_background();
  ws_.maintain_in_background();  // once is enough; again changes nothing
  const auto db_bytes = [&] { return std::filesystem::file_size(dir_ / "ws.db"); };
  const auto before = db_bytes();
  const auto folder = ws_.mkdir("/big");
  // 12 objects of 1 MB of incompressible bytes: the log passes 1000 pages three times.
  std::mt19937 rng(3);
  std::vector<SqlBlob> written;
  for (int i = 0; i < 12; ++i) {
    SqlBlob data(1 << 20);
    for (auto& b : data) b = static_cast<uint8_t>(rng());
    NewObject o;
    o.kind = ObjectKind::kImage;
    o.name = "blob" + std::to_string(i);
    o.blobs = {{"data", "bytes", data}};
    ws_.add(folder, o);
    written.push_back(std::move(data));
  }
  // The checkpoint runs on the other thread: wait for it (seconds at most on any disk).
  for (int i = 0; i < 200 && db_bytes() < before + (8u << 20); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_GE(db_bytes(), before + (8u << 20)) << "the log was not copied into the database file";
  for (int i = 0; i < 12; ++i) EXPECT_EQ(ws_.blob(ws_.resolve("/big/blob" + std::to_string(i)).id, "data"), written[size_t(i)]);
  // Closed and opened again: everything is there, and the database is sound.
  ws_ = Workspace::open(dir_ / "ws.db");
  EXPECT_EQ(ws_.children(ws_.resolve("/big").id).size(), 12u);
  EXPECT_TRUE(ws_.check().problems.empty());
}

TEST_F(WorkspaceTest, TheChangeStampCountsOwnCommitsAndSeesOthers) {
  const auto s0 = ws_.change_stamp();
  ws_.children(ws_.root());
  EXPECT_EQ(ws_.change_stamp(), s0) << "reading commits nothing";
  ws_.mkdir("/a");
  const auto s1 = ws_.change_stamp();
  EXPECT_EQ(s1.own, s0.own + 1);
  EXPECT_EQ(s1.others, s0.others) << "its own commits are not others'";
  ws_.write([&] {
    ws_.mkdir("/b");
    ws_.mkdir("/c");
  });
  EXPECT_EQ(ws_.change_stamp().own, s1.own + 1) << "one transaction, one commit";
  const auto s2 = ws_.change_stamp();
  Workspace::open(dir_ / "ws.db").mkdir("/d");
  const auto s3 = ws_.change_stamp();
  EXPECT_EQ(s3.own, s2.own);
  EXPECT_NE(s3.others, s2.others);
  EXPECT_EQ(ws_.change_stamp(), s3);
}

TEST(WorkspaceSchema, RefusesNonWorkspacesAndNewerSchemas) {
  test::TempDir dir;
  EXPECT_THROW(Workspace::open(dir / "missing.db"), Error);
  EXPECT_THROW(Workspace::create(dir / "x.db"); Workspace::create(dir / "x.db"), Error);
  { std::ofstream(dir / "text.db") << "this is not a database, just text that is long enough to be a header....."; }
  EXPECT_THROW(Workspace::open(dir / "text.db"), Error);
  {
    auto db = open_sqlite(dir / "other.db", {.create = true});
    db->execute_script("CREATE TABLE objects (x INTEGER)");
  }
  EXPECT_THROW(Workspace::open(dir / "other.db"), Error);
  {
    auto db = open_sqlite(dir / "x.db");
    db->query("UPDATE meta SET value = '99' WHERE key = 'schema_version'");
  }
  try {
    Workspace::open(dir / "x.db");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("schema version 99"), std::string::npos) << e.what();
  }
}

TEST(WorkspaceSchema, AnEmptyDatabaseIsMigratedFromVersionZero) {
  test::TempDir dir;
  { open_sqlite(dir / "empty.db", {.create = true}); }
  auto ws = Workspace::open(dir / "empty.db");
  EXPECT_EQ(ws.schema_version(), Workspace::kSchemaVersion);
  EXPECT_TRUE(ws.check().problems.empty());
}

}  // namespace
}  // namespace artisan::worldmodel
