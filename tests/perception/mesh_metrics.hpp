#pragma once
// Measuring meshes against ground truth, shared by the meshing tests and bench_meshing:
// exact point-to-triangle distances through a uniform hash grid, triangle angles.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

namespace artisan::test {

/// Closest point to p on triangle abc (Ericson, Real-Time Collision Detection, 5.1.5).
inline Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                                 const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

/// Exact point-to-triangle-soup distances up to a search radius, through a uniform hash grid
/// (cell: the radius or the median edge length, whichever is larger): every triangle is listed in
/// the cells its bounding box, grown by the radius, touches. Distances beyond the radius are
/// reported as +inf.
class TriangleDistance {
 public:
  TriangleDistance(const std::vector<Eigen::Vector3f>& vertices, const std::vector<Eigen::Vector3i>& faces,
                   double radius)
      : vertices_(vertices), faces_(faces), radius_(radius), cell_(radius) {
    std::vector<double> edges;
    for (const auto& f : faces_) edges.push_back((vertex(f[1]) - vertex(f[0])).norm());
    if (!edges.empty()) {
      std::nth_element(edges.begin(), edges.begin() + edges.size() / 2, edges.end());
      cell_ = std::max(cell_, edges[edges.size() / 2]);
    }
    for (size_t f = 0; f < faces_.size(); ++f) {
      Eigen::Vector3d lo = vertex(faces_[f][0]), hi = lo;
      for (int k = 1; k < 3; ++k) {
        lo = lo.cwiseMin(vertex(faces_[f][k]));
        hi = hi.cwiseMax(vertex(faces_[f][k]));
      }
      const auto a = cell_of(lo.array() - radius), b = cell_of(hi.array() + radius);
      for (int x = a[0]; x <= b[0]; ++x)
        for (int y = a[1]; y <= b[1]; ++y)
          for (int z = a[2]; z <= b[2]; ++z) grid_[key({x, y, z})].push_back(static_cast<uint32_t>(f));
    }
  }

  double distance(const Eigen::Vector3d& p) const {
    const auto it = grid_.find(key(cell_of(p)));
    double best = std::numeric_limits<double>::infinity();
    if (it == grid_.end()) return best;
    for (uint32_t f : it->second) {
      const auto& t = faces_[f];
      best = std::min(best, (closest_point_on_triangle(p, vertex(t[0]), vertex(t[1]), vertex(t[2])) - p).norm());
    }
    return best <= radius_ ? best : std::numeric_limits<double>::infinity();
  }

 private:
  Eigen::Vector3d vertex(int i) const { return vertices_[i].cast<double>(); }
  std::array<int, 3> cell_of(const Eigen::Vector3d& p) const {
    return {static_cast<int>(std::floor(p.x() / cell_)), static_cast<int>(std::floor(p.y() / cell_)),
            static_cast<int>(std::floor(p.z() / cell_))};
  }
  static uint64_t key(const std::array<int, 3>& c) {
    return (static_cast<uint64_t>(c[0] & 0x1fffff) << 42) | (static_cast<uint64_t>(c[1] & 0x1fffff) << 21) |
           static_cast<uint64_t>(c[2] & 0x1fffff);
  }
  const std::vector<Eigen::Vector3f>& vertices_;
  const std::vector<Eigen::Vector3i>& faces_;
  double radius_, cell_;
  std::unordered_map<uint64_t, std::vector<uint32_t>> grid_;
};

/// Smallest interior angle of a triangle [deg], in 2-D or 3-D.
template <class Vec>
double min_triangle_angle_deg(const Vec& a, const Vec& b, const Vec& c) {
  auto angle = [](const Vec& p, const Vec& q, const Vec& r) {
    const Vec e = q - p, f = r - p;
    const double cosine = e.dot(f) / (e.norm() * f.norm());
    return std::acos(std::clamp(cosine, -1.0, 1.0));
  };
  const double smallest = std::min({angle(a, b, c), angle(b, c, a), angle(c, a, b)});
  return std::isfinite(smallest) ? smallest * 180.0 / M_PI : 0.0;
}

}  // namespace artisan::test
