#pragma once
// Triangle meshes and point clouds: structs of arrays, no class hierarchy.
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "artisan/core/image.hpp"
#include "artisan/core/pose.hpp"

namespace artisan {

using Color3 = Eigen::Matrix<uint8_t, 3, 1>;

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;  ///< [m]
  std::vector<Eigen::Vector3f> normals;   ///< empty, or one unit normal per vertex
  std::vector<Eigen::Vector2f> uv;        ///< empty, or per vertex: texture coordinates in [0,1],
                                          ///< origin at the top-left of the texture (glTF)
  std::vector<Color3> colors;             ///< empty, or one RGB colour per vertex
  std::vector<Eigen::Vector3i> faces;     ///< counter-clockwise seen from outside
  ColorImage texture;                     ///< empty when there is none

  Eigen::AlignedBox3f bounds() const;
  /// Median edge length [m] (the mesh resolution); 0 for a mesh without faces.
  double median_edge_length() const;
  /// Area-weighted vertex normals from the faces (replaces `normals`).
  void compute_vertex_normals();
  /// Applies T to vertices and normals.
  void transform(const Transform& T);
  /// Appends another mesh (attributes kept only when both meshes have them).
  void append(const TriangleMesh& other);
  /// Throws artisan::Error when attribute sizes disagree, an index is out of range, or a
  /// vertex is not finite.
  void validate() const;
  bool operator==(const TriangleMesh& o) const;
};

struct PointCloud {
  std::vector<Eigen::Vector3f> points;   ///< [m]
  std::vector<Eigen::Vector3f> normals;  ///< empty, or one per point
  std::vector<Color3> colors;            ///< empty, or one per point

  Eigen::AlignedBox3f bounds() const;
  void validate() const;
};

}  // namespace artisan
