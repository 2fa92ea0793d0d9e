#include "artisan/perception/spin_image.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

#include "artisan/core/error.hpp"
#include "open_table.hpp"

namespace artisan {

SpinImageStack compute_spin_images(const PointCloud& cloud, const KdTree3& tree, const std::vector<size_t>& basis,
                                   double resolution_m, const SpinImageParams& params) {
  if (cloud.normals.size() != cloud.points.size()) throw Error("spin images: the cloud needs one normal per point");
  if (params.image_width < 2 || !(params.bin_size_factor > 0) || !(resolution_m > 0))
    throw Error("spin images: image_width " + std::to_string(params.image_width) + ", bin_size_factor " +
                std::to_string(params.bin_size_factor) + " and resolution " + std::to_string(resolution_m) + " m must be positive");
  SpinImageStack stack;
  stack.width = params.image_width;
  stack.bin_size_m = params.bin_size_factor * resolution_m;
  if (basis.empty()) {
    stack.basis.resize(cloud.points.size());
    for (size_t i = 0; i < stack.basis.size(); ++i) stack.basis[i] = i;
  } else {
    stack.basis = basis;
  }
  const int w = stack.width;
  const float b = static_cast<float>(stack.bin_size_m);
  const float half_height = 0.5f * w * b;  // beta spans [-W/2, W/2]
  const float max_alpha = w * b;
  const float support_radius = std::sqrt(max_alpha * max_alpha + half_height * half_height);
  const float min_cos = static_cast<float>(std::cos(params.support_angle_deg * M_PI / 180.0));
  stack.values.assign(stack.basis.size() * w * w, 0.0f);
#pragma omp parallel
  {
    std::vector<size_t> support;
#pragma omp for schedule(dynamic, 32)
    for (size_t k = 0; k < stack.basis.size(); ++k) {
      const Eigen::Vector3f& p = cloud.points[stack.basis[k]];
      const Eigen::Vector3f& n = cloud.normals[stack.basis[k]];
      float* image = stack.values.data() + k * w * w;
      tree.within(p, support_radius, support);
      for (size_t j : support) {
        if (cloud.normals[j].dot(n) < min_cos) continue;
        const Eigen::Vector2f ab = spin_coordinates(p, n, cloud.points[j]);
        // Row from the top (beta = +W/2) down, column from the axis out (eq. 2), bilinear.
        const float fi = (half_height - ab.y()) / b;
        const float fj = ab.x() / b;
        const int i0 = static_cast<int>(std::floor(fi)), j0 = static_cast<int>(std::floor(fj));
        if (i0 < 0 || j0 < 0 || i0 >= w - 1 || j0 >= w - 1) continue;
        const float di = fi - i0, dj = fj - j0;
        image[i0 * w + j0] += (1 - di) * (1 - dj);
        image[i0 * w + j0 + 1] += (1 - di) * dj;
        image[(i0 + 1) * w + j0] += di * (1 - dj);
        image[(i0 + 1) * w + j0 + 1] += di * dj;
      }
    }
  }
  return stack;
}

namespace {
// The mean point and normal of the oriented points in each cubic cell of a resolution, the cells
// in the order points first reach them (deterministic), each cell's sums in the order its points came.
class CellMeans {
 public:
  explicit CellMeans(double resolution_m) : inv_(1.0 / resolution_m) {}
  void add(const Eigen::Vector3f& point, const Eigen::Vector3f& normal) {
    const Eigen::Vector3d p = point.cast<double>();
    const auto key = (static_cast<uint64_t>(static_cast<int64_t>(std::floor(p.x() * inv_)) & 0x1fffff) << 42) |
                     (static_cast<uint64_t>(static_cast<int64_t>(std::floor(p.y() * inv_)) & 0x1fffff) << 21) |
                     (static_cast<uint64_t>(static_cast<int64_t>(std::floor(p.z() * inv_)) & 0x1fffff));
    const auto [place, inserted] = index_.insert(key, cells_.size());
    if (inserted) cells_.emplace_back();
    Cell& c = cells_[*place];
    c.sum_p += p;
    c.sum_n += normal.cast<double>();
    ++c.count;
  }
  PointCloud means() const {
    PointCloud out;
    for (const Cell& c : cells_) {
      const double len = c.sum_n.norm();
      if (len < 1e-9) continue;  // normals cancel: a sheet seen from both sides
      out.points.push_back((c.sum_p / c.count).cast<float>());
      out.normals.push_back((c.sum_n / len).cast<float>());
    }
    return out;
  }

 private:
  struct Cell {
    Eigen::Vector3d sum_p = Eigen::Vector3d::Zero();
    Eigen::Vector3d sum_n = Eigen::Vector3d::Zero();
    int count = 0;
  };
  double inv_;
  detail::OpenTable<size_t> index_;  ///< into cells_, by cell
  std::vector<Cell> cells_;
};
}  // namespace

PointCloud resample_oriented_points(const PointCloud& cloud, double resolution_m) {
  if (!(resolution_m > 0)) throw Error("resample: resolution " + std::to_string(resolution_m) + " m is not positive");
  if (cloud.normals.size() != cloud.points.size()) throw Error("resample: the cloud needs one normal per point");
  CellMeans cells(resolution_m);
  for (size_t i = 0; i < cloud.points.size(); ++i) cells.add(cloud.points[i], cloud.normals[i]);
  return cells.means();
}

PointCloud sample_surface(const TriangleMesh& mesh, double resolution_m) {
  if (!(resolution_m > 0)) throw Error("sample surface: resolution " + std::to_string(resolution_m) + " m is not positive");
  std::optional<TriangleMesh> with_normals;  // a copy, when the mesh has none
  if (mesh.normals.size() != mesh.vertices.size()) with_normals.emplace(mesh).compute_vertex_normals();
  const auto& v = mesh.vertices;
  const auto& vn = with_normals ? with_normals->normals : mesh.normals;
  // Points every half resolution on each face (a dense cloud of them would be a dozen per scene
  // point), averaged per cell as they come.
  const double step = 0.5 * resolution_m;
  CellMeans cells(resolution_m);
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3f &a = v[f[0]], &b = v[f[1]], &c = v[f[2]];
    Eigen::Vector3f face = (b - a).cross(c - a);
    if (!(face.norm() > 0)) continue;  // degenerate
    face.normalize();
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int n = std::clamp(static_cast<int>(std::ceil(longest / step)), 1, 4096);
    const float inv = 1.0f / static_cast<float>(n);
    // Sub-triangle centroids of the n x n split, in barycentric coordinates (i + 1/3 or 2/3).
    for (int i = 0; i < n; ++i)
      for (int j = 0; i + j < n; ++j)
        for (int up = 0; up < (i + j + 1 < n ? 2 : 1); ++up) {
          const float u = (static_cast<float>(i) + (up ? 2.0f : 1.0f) / 3.0f) * inv;
          const float w = (static_cast<float>(j) + (up ? 2.0f : 1.0f) / 3.0f) * inv;
          const float t = 1.0f - u - w;
          Eigen::Vector3f normal = t * vn[f[0]] + u * vn[f[1]] + w * vn[f[2]];
          if (!(normal.norm() > 1e-6f) || normal.normalized().dot(face) < 0.7071f) normal = face;
          cells.add(t * a + u * b + w * c, normal.normalized());
        }
  }
  return cells.means();
}

}  // namespace artisan
