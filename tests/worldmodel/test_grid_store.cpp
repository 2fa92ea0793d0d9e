// Persistent occupancy grids in the workspace (worldmodel/grid_store): the block store round
// trip, a grid that survives restarts, a mesh added in a later session giving exactly the surface
// of all meshes added at once (and of an in-memory grid), a budget smaller than the grid, bad
// input leaving the workspace unchanged, and a version-1 workspace migrating to version 2.
// Real data: bunny scans meshed in the workspace, placed at their bun.conf poses, 1 mm voxels.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "../../worldmodel/src/schema.hpp"  // the released version-1 schema script, to build a v1 workspace
#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/stanford_conf.hpp"
#include "artisan/worldmodel/grid_store.hpp"
#include "artisan/worldmodel/operations.hpp"
#include "perception/test_integration_support.hpp"
#include "test_support.hpp"

namespace artisan::worldmodel {
namespace {

const std::vector<std::string> kScans = {"bun000", "bun045", "bun315"};

// Equal meshes: the same vertices (bit for bit) and faces in the same order.
void expect_same_mesh(const TriangleMesh& a, const TriangleMesh& b) {
  ASSERT_EQ(a.vertices.size(), b.vertices.size());
  ASSERT_EQ(a.faces.size(), b.faces.size());
  size_t differing = 0;
  for (size_t i = 0; i < a.vertices.size(); ++i) differing += a.vertices[i] != b.vertices[i];
  for (size_t i = 0; i < a.faces.size(); ++i) differing += a.faces[i] != b.faces[i];
  EXPECT_EQ(differing, 0u);
}

class GridStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto ws = Workspace::create(path_);
    folder_ = ws.mkdir("/bunny");
    for (const auto& name : kScans) {
      const auto file = test::bunny_dir() / (name + ".ply");
      const auto image = ws.add(folder_, make_image_object(name, io::ply_to_range_image(io::read_ply(file), file), {"import", {}, {}}));
      mesh_[name] = run_operation(ws, "mesh", {image}, nlohmann::json::object(), folder_, name + "-mesh");
      image_[name] = image;
    }
  }
  Transform T_world(const std::string& name) const { return conf_.scan(name + ".ply").T_world_scan; }
  static GridDefinition definition() {
    GridDefinition def;
    def.voxel_size_m = 0.001;
    return def;
  }

  test::TempDir dir_;
  std::filesystem::path path_ = dir_ / "ws.db";
  ObjectId folder_ = 0;
  std::map<std::string, ObjectId> mesh_, image_;
  io::StanfordConf conf_ = io::read_stanford_conf(test::bunny_dir() / "bun.conf");
};

TEST_F(GridStoreTest, BlockStoreRoundTripsAndSealsItsBlocks) {
  ObjectId grid = 0;
  {
    auto ws = Workspace::open(path_);
    grid = create_grid(ws, folder_, "g", definition());
    WorkspaceBlockStore store(ws, grid);
    EXPECT_FALSE(store.load({1, 2, 3}).has_value());
    store.store({1, 2, 3}, {1, 2, 3, 4});
    store.store({-5, 0, 7}, {9});
    store.store({1, 2, 3}, {5, 6});  // replaces
    EXPECT_EQ(*store.load({1, 2, 3}), (std::vector<uint8_t>{5, 6}));
    EXPECT_EQ(store.keys().size(), 2u);
    EXPECT_THROW(WorkspaceBlockStore(ws, mesh_["bun000"]), Error);  // not a grid
    EXPECT_TRUE(ws.check().problems.empty());
  }
  {
    auto db = open_sqlite(path_);
    db->query("UPDATE grid_blocks SET data = x'0707' WHERE x = 1");
  }
  auto ws = Workspace::open(path_);
  WorkspaceBlockStore store(ws, grid);
  EXPECT_EQ(*store.load({-5, 0, 7}), (std::vector<uint8_t>{9}));
  try {
    store.load({1, 2, 3});
    FAIL() << "a corrupt block was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("grid block (1, 2, 3)"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(ws.check().problems.empty());
  // Removing the grid removes its blocks.
  ws.remove(grid, false);
  EXPECT_TRUE(ws.grid_block_keys(grid).empty());
}

// Method: grid A gets the three scans in one session; grid B gets bun000, then (after the
// workspace is closed and reopened, as next week) bun315 and bun045. Sums are exact integers,
// so the two extracted surfaces must be identical, and identical to an in-memory grid fed the
// same meshes with the Cyberware view the integration tests use (parallel rays along -z).
TEST_F(GridStoreTest, MeshAddedAfterARestartGivesTheSameSurfaceAsAllAtOnce) {
  ObjectId a = 0, b = 0;
  {
    auto ws = Workspace::open(path_);
    a = create_grid(ws, folder_, "a", definition());
    b = create_grid(ws, folder_, "b", definition());
    for (const auto& name : kScans) add_to_grid(ws, a, mesh_[name], T_world(name));
    const auto r = add_to_grid(ws, b, mesh_["bun000"], T_world("bun000"));
    EXPECT_GT(r.distribute.points, 10000u);
    EXPECT_GT(r.blocks, 10u);
    EXPECT_EQ(r.entry.view_mesh.rays, SensorView::Rays::kParallel);
    EXPECT_TRUE(r.entry.view_mesh.toward_sensor_mesh.isApprox(Eigen::Vector3d::UnitZ()));
  }
  auto ws = Workspace::open(path_);
  EXPECT_EQ(grid_definition(ws, b), definition());
  ASSERT_EQ(grid_meshes(ws, b).size(), 1u);
  add_to_grid(ws, b, mesh_["bun315"], T_world("bun315"));
  add_to_grid(ws, b, mesh_["bun045"], T_world("bun045"));
  const auto entries = grid_meshes(ws, b);
  ASSERT_EQ(entries.size(), 3u);
  EXPECT_EQ(entries[2].mesh, mesh_["bun045"]);
  EXPECT_EQ(entries[2].mesh_index, 2);
  EXPECT_TRUE(entries[2].T_grid_mesh.isApprox(T_world("bun045")));

  const auto merged_a = extract_grid(ws, a, folder_, "a-merged");
  const auto merged_b = extract_grid(ws, b, folder_, "b-merged");
  EXPECT_GT(merged_a.faces, 20000u);
  expect_same_mesh(ws.load_mesh(merged_a.merged), ws.load_mesh(merged_b.merged));

  InMemoryBlockStore memory;
  OccupancyGrid grid(definition(), memory);
  int index = 0;
  for (const auto& name : kScans) grid.distribute(ws.load_mesh(mesh_[name]), T_world(name), test::cyberware_view(), index++);
  expect_same_mesh(ws.load_mesh(merged_a.merged), grid.extract().mesh);

  // Provenance: the grid lists its meshes as inputs, so they cannot be removed under it; the
  // merged mesh lists the grid and the meshes.
  const auto prov = ws.provenance(merged_b.merged);
  ASSERT_TRUE(prov.has_value());
  EXPECT_EQ(prov->operation, "grid extract");
  EXPECT_EQ(prov->inputs.size(), 4u);
  EXPECT_EQ(prov->inputs[0], b);
  EXPECT_EQ(ws.get(merged_b.merged).subkind, "merged");
  EXPECT_EQ(ws.provenance(b)->inputs.size(), 3u);
  EXPECT_THROW(ws.remove(mesh_["bun045"], false), Error);
  // Extracting again makes a new version beside the first.
  const auto again = extract_grid(ws, b, folder_, "b-merged");
  EXPECT_EQ(ws.get(again.merged).version, 2);
  EXPECT_TRUE(ws.check().problems.empty());
}

// Method: the three scans into a grid of 16-voxel blocks whose budget is the minimum (8 blocks,
// about 2 MiB) while the grid needs tens of MiB, and into one with the default 256 MiB budget:
// the cache must evict,
// and the two surfaces must be identical.
TEST_F(GridStoreTest, BudgetSmallerThanTheGridGivesTheSameSurface) {
  auto ws = Workspace::open(path_);
  GridDefinition small = definition();
  small.block_edge_voxels = 16;  // small blocks: a budget of 8 of them is a small part of the grid
  small.memory_budget_bytes = 8 * (small.block_surface_bytes() + small.block_channel_bytes());
  const auto tight = create_grid(ws, folder_, "tight", small);
  GridDefinition large = definition();
  large.block_edge_voxels = 16;
  const auto roomy = create_grid(ws, folder_, "roomy", large);
  size_t evictions = 0, block_bytes = 0;
  for (const auto& name : kScans) {
    const auto r = add_to_grid(ws, tight, mesh_[name], T_world(name));
    evictions += r.cache.evictions;
    EXPECT_LE(r.cache.peak_resident_bytes, small.memory_budget_bytes);
    block_bytes = r.blocks * small.block_surface_bytes();
    add_to_grid(ws, roomy, mesh_[name], T_world(name));
  }
  EXPECT_GT(evictions, 0u);
  EXPECT_GT(block_bytes, 4 * small.memory_budget_bytes);  // the grid is several times the budget
  const auto a = extract_grid(ws, tight, folder_, "tight-merged");
  const auto b = extract_grid(ws, roomy, folder_, "roomy-merged");
  expect_same_mesh(ws.load_mesh(a.merged), ws.load_mesh(b.merged));
}

TEST_F(GridStoreTest, BadInputLeavesTheGridAsItWas) {
  auto ws = Workspace::open(path_);
  const auto grid = create_grid(ws, folder_, "g", definition());
  add_to_grid(ws, grid, mesh_["bun000"], T_world("bun000"));
  const auto before = ws.get(grid).metadata;
  const auto keys_before = ws.grid_block_keys(grid);
  const auto blob_before = ws.grid_block(grid, keys_before.front());
  auto expect_refused = [&](const std::function<void()>& fn, const std::string& words) {
    try {
      fn();
      ADD_FAILURE() << "not refused: " << words;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
    EXPECT_EQ(ws.get(grid).metadata, before);
    EXPECT_EQ(ws.grid_block_keys(grid), keys_before);
    EXPECT_EQ(ws.grid_block(grid, keys_before.front()), blob_before);
    EXPECT_EQ(ws.provenance(grid)->inputs.size(), 1u);
  };
  expect_refused([&] { add_to_grid(ws, grid, mesh_["bun000"], T_world("bun000")); }, "already in grid");
  expect_refused([&] { add_to_grid(ws, grid, image_["bun045"], T_world("bun045")); }, "not a mesh");
  Transform nan = T_world("bun045");
  nan.translation().x() = std::numeric_limits<double>::quiet_NaN();
  expect_refused([&] { add_to_grid(ws, grid, mesh_["bun045"], nan); }, "not finite");
  expect_refused([&] { add_to_grid(ws, mesh_["bun045"], mesh_["bun045"], T_world("bun045")); }, "not a grid");
  GridDefinition bad = definition();
  bad.voxel_size_m = -1;
  EXPECT_THROW(create_grid(ws, folder_, "bad", bad), Error);
  EXPECT_THROW(ws.resolve("/bunny/bad"), Error);
  EXPECT_TRUE(ws.check().problems.empty());
}

// Method: a version-1 workspace made with the released version-1 schema script (as an older build
// left it, with an object in it) opens, migrates (to version 2 and on), keeps its objects, passes check
// and takes a grid.
TEST(GridStoreMigration, VersionOneWorkspaceMigrates) {
  test::TempDir dir;
  {
    auto db = open_sqlite(dir / "v1.db", {.create = true});
    db->begin_write();
    db->execute_script(detail::migrations().at(0));
    db->query("INSERT INTO meta (key, value) VALUES ('schema_version', '1')");
    db->query("INSERT INTO objects (kind, name, created_at) VALUES ('folder', '', '2025-01-01T00:00:00.000Z')");
    db->query("INSERT INTO objects (kind, folder_id, name, created_at) VALUES ('folder', 1, 'cell', '2025-01-01T00:00:00.000Z')");
    db->commit();
    EXPECT_FALSE(db->has_table("grid_blocks"));
  }
  auto ws = Workspace::open(dir / "v1.db");
  EXPECT_EQ(ws.schema_version(), Workspace::kSchemaVersion);  // through version 2 to the newest
  EXPECT_EQ(ws.resolve("/cell").kind, ObjectKind::kFolder);
  EXPECT_TRUE(ws.check().problems.empty());
  GridDefinition def;
  const auto grid = create_grid(ws, ws.resolve("/cell").id, "g", def);
  WorkspaceBlockStore store(ws, grid);
  store.store({0, 0, 0}, {1});
  EXPECT_EQ(store.keys().size(), 1u);
  EXPECT_TRUE(ws.check().problems.empty());
}

}  // namespace
}  // namespace artisan::worldmodel
