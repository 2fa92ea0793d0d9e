// Generates the Marching Cubes case table; the rule is in marching_cubes.hpp.
#include "marching_cubes.hpp"

#include <cassert>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace artisan::mc {
namespace {

Eigen::Vector3d corner_position(int c) { return Eigen::Vector3d(c & 1, (c >> 1) & 1, (c >> 2) & 1); }

int corner_of(const std::array<int, 3>& p) { return p[0] | (p[1] << 1) | (p[2] << 2); }

// The two corners of edge e.
std::array<int, 2> edge_corners(int e) {
  auto o = edge_origin(e);
  const int a = corner_of(o);
  o[edge_axis(e)] = 1;
  return {a, corner_of(o)};
}

Eigen::Vector3d edge_midpoint(int e) {
  const auto c = edge_corners(e);
  return 0.5 * (corner_position(c[0]) + corner_position(c[1]));
}

Case make_case(int config) {
  auto inside = [config](int c) { return ((config >> c) & 1) != 0; };
  std::array<int, 12> next;
  next.fill(-1);
  // Directed segment a -> b on a face with outward normal m and inside point s: the loop runs
  // so that (b - a) x (s - mid) points into the cube, which makes the triangles face outside.
  auto add_segment = [&](int a, int b, const Eigen::Vector3d& m, const Eigen::Vector3d& s) {
    const Eigen::Vector3d d = edge_midpoint(b) - edge_midpoint(a);
    const Eigen::Vector3d mid = 0.5 * (edge_midpoint(a) + edge_midpoint(b));
    if (d.cross(s - mid).dot(m) > 0) std::swap(a, b);
    assert(next[a] == -1);
    next[a] = b;
  };
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      Eigen::Vector3d m = Eigen::Vector3d::Zero();
      m[axis] = side ? 1.0 : -1.0;
      std::vector<int> corners, edges;
      for (int c = 0; c < 8; ++c)
        if (((c >> axis) & 1) == side) corners.push_back(c);
      for (int e = 0; e < 12; ++e) {
        const auto ec = edge_corners(e);
        if (((ec[0] >> axis) & 1) == side && ((ec[1] >> axis) & 1) == side && inside(ec[0]) != inside(ec[1]))
          edges.push_back(e);
      }
      if (edges.empty()) continue;
      if (edges.size() == 2) {
        Eigen::Vector3d s = Eigen::Vector3d::Zero();
        int n = 0;
        for (int c : corners)
          if (inside(c)) s += corner_position(c), ++n;
        add_segment(edges[0], edges[1], m, s / n);
        continue;
      }
      assert(edges.size() == 4);  // diagonal corners inside: cut each inside corner off
      for (int c : corners) {
        if (!inside(c)) continue;
        std::vector<int> around;
        for (int e : edges) {
          const auto ec = edge_corners(e);
          if (ec[0] == c || ec[1] == c) around.push_back(e);
        }
        assert(around.size() == 2);
        add_segment(around[0], around[1], m, corner_position(c));
      }
    }
  }
  Case out;
  std::array<bool, 12> used{};
  for (int start = 0; start < 12; ++start) {
    if (next[start] < 0 || used[start]) continue;
    std::vector<int> loop;
    for (int e = start; !used[e]; e = next[e]) {
      used[e] = true;
      loop.push_back(e);
      assert(next[e] >= 0);
    }
    for (size_t i = 1; i + 1 < loop.size(); ++i)
      out.triangles.push_back({static_cast<uint8_t>(loop[0]), static_cast<uint8_t>(loop[i]),
                               static_cast<uint8_t>(loop[i + 1])});
  }
  return out;
}

}  // namespace

const std::array<Case, 256>& cases() {
  static const std::array<Case, 256> table = [] {
    std::array<Case, 256> t;
    for (int config = 0; config < 256; ++config) t[config] = make_case(config);
    return t;
  }();
  return table;
}

}  // namespace artisan::mc
