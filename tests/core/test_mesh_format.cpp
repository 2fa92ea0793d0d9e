// The .amsh mesh format: lossless round trips of a real mesh; corruption is detected.
#include <gtest/gtest.h>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_format.hpp"
#include "artisan/core/io/ply.hpp"
#include "test_support.hpp"

namespace artisan::io {
namespace {

TEST(MeshFormat, StanfordReconstructionRoundTripsExactlyWithAllAttributes) {
  auto mesh = ply_to_mesh(read_ply(test::bunny_dir() / "reconstruction" / "bun_zipper.ply"), "zipper");
  mesh.compute_vertex_normals();
  mesh.uv.assign(mesh.vertices.size(), Eigen::Vector2f(0.25f, 0.75f));
  mesh.colors.assign(mesh.vertices.size(), Color3(1, 2, 3));
  mesh.texture = {2, 1, 3, {1, 2, 3, 4, 5, 6}};
  for (bool compress : {true, false}) {
    const auto blob = encode_mesh(mesh, compress);
    EXPECT_TRUE(decode_mesh(blob, "zipper") == mesh);
  }
}

TEST(MeshFormat, CorruptionAndTruncationAlwaysThrow) {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.faces = {{0, 1, 2}};
  const auto blob = encode_mesh(mesh);
  for (size_t bit = 0; bit < blob.size() * 8; ++bit) {
    auto bad = blob;
    bad[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
    EXPECT_THROW(decode_mesh(bad, "flipped"), Error) << bit;
  }
  for (size_t n = 0; n < blob.size(); ++n) EXPECT_THROW(decode_mesh(std::span(blob.data(), n), "cut"), Error) << n;
}

}  // namespace
}  // namespace artisan::io
