// PLY: the real Stanford range scans and reconstruction, every encoding, and malformed files.
#include <gtest/gtest.h>

#include <map>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "test_support.hpp"

namespace artisan::io {
namespace {

using test::bunny_dir;

std::vector<uint8_t> bytes_of(const std::string& s) { return {s.begin(), s.end()}; }

// Vertex counts from the headers of the Stanford originals (ground truth for the reader).
const std::map<std::string, size_t> kVertexCounts = {
    {"bun000", 40256}, {"bun045", 40097}, {"bun090", 30379}, {"bun180", 40251}, {"bun270", 31701},
    {"bun315", 35336}, {"chin", 37738},   {"ear_back", 32193}, {"top2", 38298}, {"top3", 36023}};

TEST(Ply, EveryBunnyScanIsA512x400RangeImageWithItsExactVertexCount) {
  for (const auto& [name, count] : kVertexCounts) {
    const auto path = bunny_dir() / (name + ".ply");
    const auto image = ply_to_range_image(read_ply(path), path);
    EXPECT_EQ(image.width, 512) << name;
    EXPECT_EQ(image.height, 400) << name;
    EXPECT_EQ(image.valid_count(), count) << name;
    EXPECT_EQ(image.sensor.kind, "cyberware") << name;
    EXPECT_EQ(image.sensor.attributes.at("num_cols"), "512");
    EXPECT_NO_THROW(image.validate());
    // The bunny is about 15 cm across.
    const Eigen::Vector3f size = image.bounds().sizes();
    EXPECT_GT(size.maxCoeff(), 0.08f) << name;
    EXPECT_LT(size.maxCoeff(), 0.25f) << name;
  }
}

TEST(Ply, AsciiOriginalAndBinaryCopyReadIdentically) {
  const auto ascii = read_ply(bunny_dir() / "bun000_ascii.ply");
  const auto binary = read_ply(bunny_dir() / "bun000.ply");
  EXPECT_EQ(ascii.format, PlyFormat::kAscii);
  EXPECT_EQ(binary.format, PlyFormat::kBinaryLittleEndian);
  const auto a = ply_to_range_image(ascii, "ascii");
  const auto b = ply_to_range_image(binary, "binary");
  EXPECT_TRUE(a == b);
  // First vertex of the ASCII file: "-0.06325 0.0359793 0.0420873".
  const auto* x = ascii.find("vertex")->find("x");
  EXPECT_FLOAT_EQ(static_cast<float>(x->values[0]), -0.06325f);
}

TEST(Ply, ImageRowZeroIsTheTopOfTheScan) {
  // Cyberware grids store the bottom scanline first; our images put row 0 at the top, so the
  // scanner's y (up) decreases down the image.
  const auto image = ply_to_range_image(read_ply(bunny_dir() / "bun000.ply"), "bun000");
  double top = 0, bottom = 0;
  int n_top = 0, n_bottom = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const auto i = image.index(x, y);
      if (!image.valid[i]) continue;
      (y < image.height / 2 ? top : bottom) += image.points_sensor[i].y();
      ++(y < image.height / 2 ? n_top : n_bottom);
    }
  EXPECT_GT(top / n_top, bottom / n_bottom + 0.03);
}

TEST(Ply, StanfordReconstructionIsAMesh) {
  const auto path = bunny_dir() / "reconstruction" / "bun_zipper.ply";
  const auto ply = read_ply(path);
  const auto mesh = ply_to_mesh(ply, path);
  EXPECT_EQ(mesh.vertices.size(), 35947u);
  EXPECT_EQ(mesh.faces.size(), 69451u);
  EXPECT_NO_THROW(mesh.validate());
  // It keeps its extra vertex properties at the generic level.
  EXPECT_NE(ply.find("vertex")->find("confidence"), nullptr);
}

TEST(Ply, RangeImageRoundTripsInEveryEncoding) {
  test::TempDir dir;
  const auto image = ply_to_range_image(read_ply(bunny_dir() / "bun090.ply"), "bun090");
  for (auto format : {PlyFormat::kAscii, PlyFormat::kBinaryLittleEndian, PlyFormat::kBinaryBigEndian}) {
    const auto path = dir / "out.ply";
    write_ply(range_image_to_ply(image, format), path);
    const auto ply = read_ply(path);
    EXPECT_EQ(ply.format, format);
    EXPECT_TRUE(ply_to_range_image(ply, path) == image) << static_cast<int>(format);
  }
}

TEST(Ply, MeshWithAllAttributesRoundTripsInEveryEncoding) {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0.5f}};
  mesh.normals = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0.6f, 0.8f}};
  mesh.uv = {{0, 0}, {1, 0}, {0, 1}, {1, 1}};
  mesh.colors = {Color3(255, 0, 0), Color3(0, 255, 0), Color3(0, 0, 255), Color3(7, 8, 9)};
  mesh.faces = {{0, 1, 2}, {1, 3, 2}};
  for (auto format : {PlyFormat::kAscii, PlyFormat::kBinaryLittleEndian, PlyFormat::kBinaryBigEndian}) {
    const auto bytes = serialize_ply(mesh_to_ply(mesh, format));
    EXPECT_TRUE(ply_to_mesh(parse_ply(bytes, "memory"), "memory") == mesh);
  }
}

TEST(Ply, PolygonsAreFanTriangulatedAndOtherTypesRead) {
  const std::string text =
      "ply\nformat ascii 1.0\ncomment a quad and a triangle\nelement vertex 5\nproperty double x\n"
      "property double y\nproperty double z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
      "element face 2\nproperty list uint8 uint32 vertex_index\nend_header\n"
      "0 0 0 1 2 3\n1 0 0 1 2 3\n1 1 0 1 2 3\n0 1 0 1 2 3\n2 2 2 1 2 3\n4 0 1 2 3\n3 2 3 4\n";
  const auto ply = parse_ply(bytes_of(text), "quad.ply");
  ASSERT_EQ(ply.comments.size(), 1u);
  const auto mesh = ply_to_mesh(ply, "quad.ply");
  ASSERT_EQ(mesh.faces.size(), 3u);
  EXPECT_EQ(mesh.faces[0], Eigen::Vector3i(0, 1, 2));
  EXPECT_EQ(mesh.faces[1], Eigen::Vector3i(0, 2, 3));
  EXPECT_EQ(mesh.colors[4], Color3(1, 2, 3));
}

void expect_error(const std::string& text, const std::string& fragment, bool as_mesh = true) {
  try {
    const auto ply = parse_ply(bytes_of(text), "bad.ply");
    if (as_mesh) ply_to_mesh(ply, "bad.ply");
    else ply_to_range_image(ply, "bad.ply");
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.ply"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(Ply, MalformedFilesThrowNamingFileAndDefect) {
  const std::string head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string face = "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  expect_error("", "empty file");
  expect_error("plx\n", "not a PLY file");
  expect_error("ply\nformat ascii 1.0\nelement vertex 1\n", "end_header");
  expect_error("ply\nformat ascii 2.0\nend_header\n", "version");
  expect_error("ply\nformat ascii 1.0\nelement vertex 1\nproperty quux x\nend_header\n1\n", "unknown type");
  expect_error(head + face + "0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n", "refers to vertex 5");
  expect_error(head + face + "0 0 0\n1 0 0\n0 1 0\n", "truncated");
  expect_error(head + face + "0 0 0\n1 0 0\nnan 1 0\n3 0 1 2\n", "not finite");
  expect_error(head + face + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n7\n", "after the last element");
  expect_error(head + face + "0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "at least 3");
  expect_error(head + face + "0 0 0\n1 0 0\n0 1 zero\n3 0 1 2\n", "is not a number");
  expect_error(head + "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n300 0 1 2\n",
               "does not fit type uchar");
  expect_error("ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\nend_header\n\x01\x02",
               "declares 99999999999 entries");
  // Range grids: counts must agree with obj_info.
  expect_error("ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 2\n" + head.substr(21) +
                   "element range_grid 3\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 0\n1 1\n1 2\n",
               "range_grid has 3 cells", false);
  expect_error("ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 2\n" + head.substr(21) +
                   "element range_grid 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 0\n1 1\n0\n0\n",
               "not on the range grid", false);
}

}  // namespace
}  // namespace artisan::io
