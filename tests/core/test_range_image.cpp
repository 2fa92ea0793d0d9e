// Core geometry types: range image, triangle mesh, camera; analytic cases.
#include <gtest/gtest.h>

#include "artisan/core/camera.hpp"
#include "artisan/core/error.hpp"
#include "artisan/core/range_image.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan {
namespace {

TEST(RangeImage, EmptyOfSizeHasPixelUvAndNoValidPixels) {
  const auto image = RangeImage::empty_of_size(4, 3);
  EXPECT_EQ(image.pixel_count(), 12u);
  EXPECT_EQ(image.valid_count(), 0u);
  EXPECT_EQ(image.uv[image.index(3, 2)], Eigen::Vector2f(3, 2));
  EXPECT_TRUE(image.bounds().isEmpty());
  EXPECT_THROW(RangeImage::empty_of_size(0, 3), Error);
}

TEST(RangeImage, ValidateRejectsNonFiniteValidPointsAndSizeMismatch) {
  auto image = RangeImage::empty_of_size(2, 2);
  image.points_sensor[1] = Eigen::Vector3f(NAN, 0, 0);
  EXPECT_NO_THROW(image.validate());  // invalid pixels may hold anything
  image.valid[1] = 1;
  EXPECT_THROW(image.validate(), Error);
  image.points_sensor[1] = Eigen::Vector3f(1, 2, 3);
  EXPECT_NO_THROW(image.validate());
  EXPECT_EQ(image.bounds().min(), Eigen::Vector3f(1, 2, 3));
  image.uv.pop_back();
  EXPECT_THROW(image.validate(), Error);
}

TEST(PinholeCamera, UnprojectInvertsProject) {
  const PinholeCamera cam{640, 480, 525.0, 525.0, 319.5, 239.5};
  EXPECT_NO_THROW(cam.validate());
  const Eigen::Vector3d p(0.1, -0.2, 1.5);
  const auto uv = cam.project(p);
  ASSERT_TRUE(uv.has_value());
  EXPECT_TRUE(cam.unproject(*uv, 1.5).isApprox(p, 1e-12));
  EXPECT_FALSE(cam.project({0, 0, -1}).has_value());
  EXPECT_THROW((PinholeCamera{0, 480, 525, 525, 0, 0}.validate()), Error);
}

TriangleMesh unit_square() {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  m.faces = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

TEST(TriangleMesh, NormalsOfACounterClockwiseSquarePointUp) {
  auto m = unit_square();
  m.compute_vertex_normals();
  for (const auto& n : m.normals) EXPECT_TRUE(n.isApprox(Eigen::Vector3f::UnitZ()));
}

TEST(TriangleMesh, MedianEdgeLengthOfUnitSquare) {
  // Edges: four sides of length 1 (the diagonal counted twice): median is 1.
  EXPECT_FLOAT_EQ(unit_square().median_edge_length(), 1.0f);
  EXPECT_EQ(TriangleMesh{}.median_edge_length(), 0.0);
}

TEST(TriangleMesh, TransformMovesVerticesAndRotatesNormals) {
  auto m = unit_square();
  m.compute_vertex_normals();
  Transform T = Transform::Identity();
  T.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0, 0, 1);
  m.transform(T);
  EXPECT_TRUE(m.vertices[2].isApprox(Eigen::Vector3f(1, 0, 2), 1e-6f));
  EXPECT_TRUE(m.normals[0].isApprox(Eigen::Vector3f(0, -1, 0), 1e-6f));
}

TEST(TriangleMesh, AppendOffsetsFacesAndDropsAttributesOnlyOneSideHas) {
  auto a = unit_square();
  auto b = unit_square();
  b.compute_vertex_normals();
  a.append(b);
  EXPECT_EQ(a.vertices.size(), 8u);
  EXPECT_EQ(a.faces.back(), Eigen::Vector3i(4, 6, 7));
  EXPECT_TRUE(a.normals.empty());
  EXPECT_NO_THROW(a.validate());
  TriangleMesh c;
  c.append(b);  // appending to an empty mesh keeps everything
  EXPECT_TRUE(c == b);
}

TEST(TriangleMesh, ValidateNamesTheDefect) {
  auto m = unit_square();
  m.faces.push_back({0, 1, 9});
  try {
    m.validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("face 2 refers to vertex 9"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace artisan
