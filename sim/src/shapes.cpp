#include "artisan/sim/shapes.hpp"

#include <cmath>
#include <numbers>
#include <vector>

namespace artisan::sim {

namespace {

constexpr double kPi = std::numbers::pi;

// A frame along a swept path: centre and two unit vectors spanning the cross-section.
struct RingFrame {
  Eigen::Vector3d centre;
  Eigen::Vector3d e1;
  Eigen::Vector3d e2;
};

// The side surface of a circle of `radius` swept through `frames`. Outward normals when
// `outward`, otherwise facing the axis (the inside wall of a pipe).
TriangleMesh sweep(const std::vector<RingFrame>& frames, double radius, int segments, bool outward) {
  TriangleMesh m;
  for (const auto& f : frames) {
    for (int s = 0; s <= segments; ++s) {
      const double a = 2 * kPi * s / segments;
      const Eigen::Vector3d dir = std::cos(a) * f.e1 + std::sin(a) * f.e2;
      m.vertices.push_back((f.centre + radius * dir).cast<float>());
      m.normals.push_back((outward ? dir : Eigen::Vector3d(-dir)).cast<float>());
    }
  }
  const int row = segments + 1;
  for (size_t i = 0; i + 1 < frames.size(); ++i) {
    // Orientation: the sweep direction d = e1 x e2 (frames are built that way).
    for (int s = 0; s < segments; ++s) {
      const int a = static_cast<int>(i) * row + s, b = a + 1, c = a + row, d = c + 1;
      if (outward) {
        m.faces.emplace_back(a, b, d);
        m.faces.emplace_back(a, d, c);
      } else {
        m.faces.emplace_back(a, d, b);
        m.faces.emplace_back(a, c, d);
      }
    }
  }
  return m;
}

// A flat annulus (or disc when inner == 0) in the plane of `f`, facing +n or -n (n = e1 x e2).
TriangleMesh annulus(const RingFrame& f, double inner, double outer, int segments, bool facing_plus) {
  TriangleMesh m;
  const Eigen::Vector3f n = (facing_plus ? f.e1.cross(f.e2) : Eigen::Vector3d(-f.e1.cross(f.e2))).cast<float>();
  for (int s = 0; s <= segments; ++s) {
    const double a = 2 * kPi * s / segments;
    const Eigen::Vector3d dir = std::cos(a) * f.e1 + std::sin(a) * f.e2;
    m.vertices.push_back((f.centre + inner * dir).cast<float>());
    m.vertices.push_back((f.centre + outer * dir).cast<float>());
    m.normals.push_back(n);
    m.normals.push_back(n);
  }
  for (int s = 0; s < segments; ++s) {
    const int i0 = 2 * s, o0 = i0 + 1, i1 = i0 + 2, o1 = i0 + 3;
    if (facing_plus) {
      m.faces.emplace_back(i0, o0, o1);
      m.faces.emplace_back(i0, o1, i1);
    } else {
      m.faces.emplace_back(i0, o1, o0);
      m.faces.emplace_back(i0, i1, o1);
    }
  }
  return m;
}

RingFrame frame_z(double z) { return {{0, 0, z}, Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY()}; }

// Hollow tube along z from z0 to z1.
TriangleMesh tube(double r_out, double r_in, double z0, double z1, int segments) {
  TriangleMesh m = sweep({frame_z(z0), frame_z(z1)}, r_out, segments, true);
  if (r_in > 0) m.append(sweep({frame_z(z0), frame_z(z1)}, r_in, segments, false));
  m.append(annulus(frame_z(z1), r_in, r_out, segments, true));
  m.append(annulus(frame_z(z0), r_in, r_out, segments, false));
  return m;
}

TriangleMesh transformed(TriangleMesh m, const Transform& T) {
  m.transform(T);
  return m;
}

}  // namespace

TriangleMesh make_box(const Eigen::Vector3d& size) {
  TriangleMesh m;
  const Eigen::Vector3f h = (size / 2).cast<float>();
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      Eigen::Vector3f n = Eigen::Vector3f::Zero();
      n[axis] = static_cast<float>(sign);
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      const int base = static_cast<int>(m.vertices.size());
      for (int k = 0; k < 4; ++k) {
        Eigen::Vector3f p;
        p[axis] = sign * h[axis];
        p[u] = ((k == 1 || k == 2) ? 1.f : -1.f) * h[u];
        p[v] = (k >= 2 ? 1.f : -1.f) * h[v];
        m.vertices.push_back(p);
        m.normals.push_back(n);
      }
      // (u, v) is right-handed around +axis: counter-clockwise seen from +axis.
      if (sign > 0) {
        m.faces.emplace_back(base, base + 1, base + 2);
        m.faces.emplace_back(base, base + 2, base + 3);
      } else {
        m.faces.emplace_back(base, base + 2, base + 1);
        m.faces.emplace_back(base, base + 3, base + 2);
      }
    }
  }
  return m;
}

TriangleMesh make_sphere(double radius, int segments) {
  TriangleMesh m;
  const int rings = segments / 2;
  for (int r = 0; r <= rings; ++r) {
    const double theta = kPi * r / rings;
    for (int s = 0; s <= segments; ++s) {
      const double phi = 2 * kPi * s / segments;
      const Eigen::Vector3d n(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
      m.vertices.push_back((radius * n).cast<float>());
      m.normals.push_back(n.cast<float>());
    }
  }
  const int row = segments + 1;
  for (int r = 0; r < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      const int a = r * row + s, b = a + 1, c = a + row, d = c + 1;
      if (r > 0) m.faces.emplace_back(a, c, b);
      if (r + 1 < rings) m.faces.emplace_back(b, c, d);
    }
  return m;
}

TriangleMesh make_cylinder(double radius, double length, int segments) {
  return tube(radius, 0.0, -length / 2, length / 2, segments);
}

TriangleMesh make_pipe(double length, const PipeSize& size) {
  const double r = size.outer_diameter_m / 2;
  return tube(r, r - size.wall_m, -length / 2, length / 2, size.segments);
}

TriangleMesh make_elbow(double bend_radius, const PipeSize& size) {
  const double r = size.outer_diameter_m / 2;
  const int steps = 16;
  std::vector<RingFrame> frames;
  for (int i = 0; i <= steps; ++i) {
    // Bend centre at (R, 0, 0); the axis leaves the origin along +z and ends along +x.
    const double a = (kPi / 2) * i / steps;
    const Eigen::Vector3d centre(bend_radius * (1 - std::cos(a)), 0, bend_radius * std::sin(a));
    const Eigen::Vector3d tangent(std::sin(a), 0, std::cos(a));
    const Eigen::Vector3d e2 = Eigen::Vector3d::UnitY();
    frames.push_back({centre, e2.cross(tangent), e2});  // e1 x e2 = tangent
  }
  TriangleMesh m = sweep(frames, r, size.segments, true);
  m.append(sweep(frames, r - size.wall_m, size.segments, false));
  m.append(annulus(frames.front(), r - size.wall_m, r, size.segments, false));
  m.append(annulus(frames.back(), r - size.wall_m, r, size.segments, true));
  return m;
}

TriangleMesh make_tee(double run_length, double branch_length, const PipeSize& size) {
  const double r = size.outer_diameter_m / 2;
  TriangleMesh m = tube(r, r - size.wall_m, -run_length / 2, run_length / 2, size.segments);
  // The branch starts inside the run (at its axis) so the union has no gap.
  Transform T_tee_branch = Transform::Identity();
  T_tee_branch.linear() = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  m.append(transformed(tube(r, r - size.wall_m, r * 0.5, branch_length, size.segments), T_tee_branch));
  return m;
}

TriangleMesh make_flange(double flange_diameter, double thickness, double neck_length, const PipeSize& size) {
  const double r = size.outer_diameter_m / 2, ri = r - size.wall_m;
  TriangleMesh m = tube(flange_diameter / 2, ri, 0.0, thickness, size.segments * 2);
  m.append(tube(r, ri, thickness, thickness + neck_length, size.segments));
  return m;
}

TriangleMesh make_valve(double length, const PipeSize& size) {
  const double r = size.outer_diameter_m / 2, ri = r - size.wall_m;
  const double body_r = 1.1 * size.outer_diameter_m;
  TriangleMesh m = make_sphere(body_r, size.segments);
  m.append(tube(r * 1.15, ri, -length / 2, -body_r * 0.8, size.segments));
  m.append(tube(r * 1.15, ri, body_r * 0.8, length / 2, size.segments));
  // Stem along +x and a hand wheel (a flat ring) at its end.
  Transform T_valve_stem = Transform::Identity();
  T_valve_stem.linear() = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const double stem_end = body_r + 0.12;
  m.append(transformed(tube(0.012, 0.0, body_r * 0.9, stem_end, 16), T_valve_stem));
  m.append(transformed(tube(0.09, 0.075, stem_end, stem_end + 0.015, 48), T_valve_stem));
  m.append(transformed(make_box({0.012, 0.16, 0.012}), Transform(Eigen::Translation3d(stem_end + 0.0075, 0, 0))));
  return m;
}

}  // namespace artisan::sim
