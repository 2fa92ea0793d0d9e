// Meshes through assimp and the project's writers, on real robot meshes.
#include <gtest/gtest.h>

#include <fstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_io.hpp"
#include "test_support.hpp"

namespace artisan::io {
namespace {

const auto kUr5 = test::data_dir() / "robots" / "ur5";

TEST(MeshIo, Ur5VisualColladaAndCollisionStlDescribeTheSameLink) {
  // Method: the visual (COLLADA, Z-up, metres) and collision (STL) meshes of a real UR5 link
  // were made to coincide; read in the file's own frame they must have the same bounds.
  for (const std::string link : {"base", "forearm"}) {
    const auto visual = read_mesh(kUr5 / (link + "_visual.dae"));
    const auto collision = read_mesh(kUr5 / (link + "_collision.stl"));
    EXPECT_GT(visual.faces.size(), 500u) << link;
    EXPECT_GT(collision.faces.size(), 100u) << link;
    EXPECT_FALSE(visual.normals.empty());
    const auto bv = visual.bounds(), bc = collision.bounds();
    EXPECT_LT((bv.min() - bc.min()).norm(), 0.005f) << link;
    EXPECT_LT((bv.max() - bc.max()).norm(), 0.005f) << link;
  }
}

TEST(MeshIo, StanfordReconstructionRoundTripsThroughEveryWritableFormat) {
  const auto mesh = read_mesh(test::bunny_dir() / "reconstruction" / "bun_zipper.ply");
  ASSERT_EQ(mesh.faces.size(), 69451u);
  test::TempDir dir;
  for (const std::string ext : {".ply", ".obj", ".stl", ".glb", ".gltf"}) {
    const auto path = dir / ("bunny" + ext);
    write_mesh(mesh, path);
    const auto back = read_mesh(path);
    EXPECT_EQ(back.faces.size(), mesh.faces.size()) << ext;
    // Vertex order may change (assimp joins identical vertices), so compare geometry.
    EXPECT_TRUE(back.bounds().min().isApprox(mesh.bounds().min(), 1e-6f)) << ext;
    EXPECT_TRUE(back.bounds().max().isApprox(mesh.bounds().max(), 1e-6f)) << ext;
    EXPECT_NEAR(back.median_edge_length(), mesh.median_edge_length(), 1e-6) << ext;
  }
  EXPECT_TRUE(read_mesh(dir / "bunny.ply") == mesh);  // our own PLY is exact
}

TEST(MeshIo, AttributesSurviveObjAndGltf) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.normals = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  m.uv = {{0, 0.25f}, {1, 0.25f}, {0, 1}};
  m.faces = {{0, 1, 2}};
  test::TempDir dir;
  for (const std::string ext : {".obj", ".glb"}) {
    write_mesh(m, dir / ("t" + ext));
    const auto back = read_mesh(dir / ("t" + ext));
    ASSERT_EQ(back.vertices.size(), 3u) << ext;
    ASSERT_EQ(back.uv.size(), 3u) << ext;
    for (size_t i = 0; i < 3; ++i) {
      // Match by position: the reader may reorder.
      for (size_t j = 0; j < 3; ++j)
        if (back.vertices[j] == m.vertices[i]) {
          EXPECT_TRUE(back.uv[j].isApprox(m.uv[i])) << ext;
          EXPECT_TRUE(back.normals[j].isApprox(m.normals[i])) << ext;
        }
    }
  }
}

TEST(MeshIo, BadFilesThrowNamingTheFile) {
  test::TempDir dir;
  std::ofstream(dir / "empty.obj").close();
  std::ofstream(dir / "junk.stl") << "solid junk\nthis is not an stl\n";
  std::ofstream(dir / "nofaces.obj") << "v 0 0 0\nv 1 0 0\n";
  for (const std::string name : {"empty.obj", "junk.stl", "nofaces.obj", "missing.dae"}) {
    try {
      read_mesh(dir / name);
      ADD_FAILURE() << name;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(write_mesh(TriangleMesh{}, dir / "x.xyz"), FileError);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.xyz"));
}

}  // namespace
}  // namespace artisan::io
