#include "artisan/core/triangle_mesh.hpp"

#include <algorithm>
#include <string>

#include "artisan/core/error.hpp"

namespace artisan {

Eigen::AlignedBox3f TriangleMesh::bounds() const {
  Eigen::AlignedBox3f box;
  for (const auto& v : vertices) box.extend(v);
  return box;
}

double TriangleMesh::median_edge_length() const {
  if (faces.empty()) return 0.0;
  std::vector<float> lengths;
  lengths.reserve(faces.size() * 3);
  for (const auto& f : faces)
    for (int k = 0; k < 3; ++k) lengths.push_back((vertices[f[k]] - vertices[f[(k + 1) % 3]]).norm());
  auto mid = lengths.begin() + lengths.size() / 2;
  std::nth_element(lengths.begin(), mid, lengths.end());
  return *mid;
}

void TriangleMesh::compute_vertex_normals() {
  normals.assign(vertices.size(), Eigen::Vector3f::Zero());
  for (const auto& f : faces) {
    // The cross product's length is twice the area: area weighting comes for free.
    const Eigen::Vector3f n = (vertices[f[1]] - vertices[f[0]]).cross(vertices[f[2]] - vertices[f[0]]);
    for (int k = 0; k < 3; ++k) normals[f[k]] += n;
  }
  for (auto& n : normals) {
    const float len = n.norm();
    n = len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f::Zero();
  }
}

void TriangleMesh::transform(const Transform& T) {
  const Eigen::Matrix3f R = T.linear().cast<float>();
  const Eigen::Vector3f t = T.translation().cast<float>();
  for (auto& v : vertices) v = R * v + t;
  for (auto& n : normals) n = R * n;
}

void TriangleMesh::append(const TriangleMesh& other) {
  const bool keep_normals = normals.size() == vertices.size() && other.normals.size() == other.vertices.size();
  const bool keep_uv = uv.size() == vertices.size() && other.uv.size() == other.vertices.size();
  const bool keep_colors = colors.size() == vertices.size() && other.colors.size() == other.vertices.size();
  const bool first = vertices.empty();
  const int offset = static_cast<int>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  if (keep_normals || (first && !other.normals.empty())) normals.insert(normals.end(), other.normals.begin(), other.normals.end()); else normals.clear();
  if (keep_uv || (first && !other.uv.empty())) uv.insert(uv.end(), other.uv.begin(), other.uv.end()); else uv.clear();
  if (keep_colors || (first && !other.colors.empty())) colors.insert(colors.end(), other.colors.begin(), other.colors.end()); else colors.clear();
  for (const auto& f : other.faces) faces.push_back(f.array() + offset);
  if (first) texture = other.texture;
}

void TriangleMesh::validate() const {
  const size_t n = vertices.size();
  auto check_size = [n](size_t size, const char* what) {
    if (size != 0 && size != n)
      throw Error(std::string("mesh has ") + std::to_string(size) + " " + what + " for " + std::to_string(n) + " vertices");
  };
  check_size(normals.size(), "normals");
  check_size(uv.size(), "texture coordinates");
  check_size(colors.size(), "colours");
  for (size_t i = 0; i < n; ++i)
    if (!vertices[i].allFinite()) throw Error("mesh vertex " + std::to_string(i) + " is not finite");
  for (size_t i = 0; i < normals.size(); ++i)
    if (!normals[i].allFinite()) throw Error("mesh normal " + std::to_string(i) + " is not finite");
  for (size_t i = 0; i < faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      if (faces[i][k] < 0 || static_cast<size_t>(faces[i][k]) >= n)
        throw Error("mesh face " + std::to_string(i) + " refers to vertex " + std::to_string(faces[i][k]) + " of " +
                    std::to_string(n));
    }
  }
}

bool TriangleMesh::operator==(const TriangleMesh& o) const {
  return vertices == o.vertices && normals == o.normals && uv == o.uv && colors == o.colors && faces == o.faces &&
         texture == o.texture;
}

Eigen::AlignedBox3f PointCloud::bounds() const {
  Eigen::AlignedBox3f box;
  for (const auto& p : points) box.extend(p);
  return box;
}

void PointCloud::validate() const {
  if (!normals.empty() && normals.size() != points.size())
    throw Error("point cloud has " + std::to_string(normals.size()) + " normals for " + std::to_string(points.size()) + " points");
  if (!colors.empty() && colors.size() != points.size())
    throw Error("point cloud has " + std::to_string(colors.size()) + " colours for " + std::to_string(points.size()) + " points");
  for (size_t i = 0; i < points.size(); ++i)
    if (!points[i].allFinite()) throw Error("point " + std::to_string(i) + " is not finite");
}

}  // namespace artisan
