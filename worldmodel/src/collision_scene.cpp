// Collision scene: each body's triangles in a bounding-volume hierarchy of its own (binary AABB
// tree split at the median centroid of the longest axis, leaves of up to 4 triangles whose
// vertices are stored in leaf order), in the body frame. A query shape is moved into each body's
// frame and walks the tree:
//  - pruning, never deciding: a node or triangle is skipped only when a lower bound of its
//    distance to the shape exceeds the reach (the body's margin for collision; the best distance
//    so far for distance queries). Lower bounds: the gap between axis-aligned boxes, and the
//    separating-axis gaps against the shape's oriented bounding box (its 3 axes for nodes; for
//    triangles all 13 box/triangle axes, Akenine-Moeller 2001, which for a box is exact);
//    Boxes and convex hulls also prune by their own vertices: the hull's box in the body frame
//    and the triangle's normal axis;
//  - deciding, exactly, per surviving triangle: closest point on the triangle for spheres
//    (Ericson, Real-Time Collision Detection 5.1.5); for boxes and hulls, GJK on their vertices
//    (a vectorized support, warm-started from the last separating direction, witnesses from the
//    simplex's barycentric weights); Bullet's GJK/EPA for cylinders and capsules, and for boxes
//    and hulls that penetrate (the depth is EPA's). Bullet's GJK on a hull is about four times
//    slower per triangle and stops up to 0.4 mm short of the true distance.
// Collision checks stop a (shape, body) pair at its first colliding triangle unless the deepest
// contact is asked for; distance queries visit nearer children first and shrink the reach as
// they go (closest pair with branch and bound), as FCL does, and stop at the first penetration.
#include "artisan/worldmodel/collision_scene.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <numeric>
#include <unordered_map>

#include <btBulletCollisionCommon.h>
#include <BulletCollision/CollisionShapes/btTriangleShape.h>
#include <BulletCollision/NarrowPhaseCollision/btGjkEpaPenetrationDepthSolver.h>
#include <BulletCollision/NarrowPhaseCollision/btGjkPairDetector.h>
#include <BulletCollision/NarrowPhaseCollision/btPointCollector.h>
#include <BulletCollision/NarrowPhaseCollision/btVoronoiSimplexSolver.h>

#include "artisan/core/error.hpp"

namespace artisan::worldmodel {

// The hierarchy over one mesh, in the body frame.
class BodyGeometry {
 public:
  struct Node {
    Eigen::Vector3f lo, hi;
    int32_t index = 0;  ///< leaf: first triangle; inner node: first of its two children
    int32_t count = 0;  ///< leaf: number of triangles; inner node: 0
  };
  struct Tri {
    Eigen::Vector3f a, b, c;
  };
  std::shared_ptr<const TriangleMesh> mesh;
  std::vector<Node> nodes;  ///< nodes[0] is the root
  std::vector<Tri> tris;    ///< in leaf order
};

namespace {

// Query shapes keep a small margin: GJK is robust with one, and boxes/cylinders keep their size
// (Bullet puts their margin inside); hulls are shrunk by it towards their centroid.
constexpr double kShapeMargin = 1e-4;
constexpr int kLeafSize = 4;

btTransform to_bt(const Transform& T) {
  const Eigen::Matrix3d R = T.rotation();
  btMatrix3x3 basis(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1), R(2, 2));
  return btTransform(basis, btVector3(T.translation().x(), T.translation().y(), T.translation().z()));
}

btVector3 to_bt(const Eigen::Vector3f& v) { return btVector3(v.x(), v.y(), v.z()); }
Eigen::Vector3d to_eigen(const btVector3& v) { return {v.x(), v.y(), v.z()}; }

bool finite_pose(const Transform& T) { return T.matrix().allFinite(); }

using Geometry = BodyGeometry;

std::shared_ptr<Geometry> build(std::shared_ptr<const TriangleMesh> mesh) {
  if (mesh->faces.empty()) throw Error("collision scene: a body mesh has no triangles");
  mesh->validate();
  auto g = std::make_shared<Geometry>();
  g->mesh = mesh;
  const auto& V = mesh->vertices;
  const auto& F = mesh->faces;
  const int n = int(F.size());
  std::vector<int32_t> order(F.size());
  std::iota(order.begin(), order.end(), 0);
  std::vector<Eigen::Vector3f> centroid(F.size());
  for (int i = 0; i < n; ++i) {
    const auto& f = F[size_t(i)];
    centroid[size_t(i)] = (V[size_t(f[0])] + V[size_t(f[1])] + V[size_t(f[2])]) / 3.0f;
  }
  g->nodes.reserve(size_t(2 * (n / kLeafSize + 1)));
  g->nodes.emplace_back();
  struct Task {
    int node, begin, end;
  };
  std::vector<Task> tasks{{0, 0, n}};
  while (!tasks.empty()) {
    const Task t = tasks.back();
    tasks.pop_back();
    Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max()), hi = -lo;
    Eigen::Vector3f clo = lo, chi = hi;
    for (int i = t.begin; i < t.end; ++i) {
      const auto& f = F[size_t(order[size_t(i)])];
      for (int k = 0; k < 3; ++k) {
        lo = lo.cwiseMin(V[size_t(f[k])]);
        hi = hi.cwiseMax(V[size_t(f[k])]);
      }
      clo = clo.cwiseMin(centroid[size_t(order[size_t(i)])]);
      chi = chi.cwiseMax(centroid[size_t(order[size_t(i)])]);
    }
    auto& node = g->nodes[size_t(t.node)];
    node.lo = lo;
    node.hi = hi;
    if (t.end - t.begin <= kLeafSize) {
      node.index = t.begin;
      node.count = t.end - t.begin;
      continue;
    }
    int axis = 0;
    (chi - clo).maxCoeff(&axis);
    const int mid = (t.begin + t.end) / 2;
    std::nth_element(order.begin() + t.begin, order.begin() + mid, order.begin() + t.end,
                     [&](int32_t a, int32_t b) { return centroid[size_t(a)][axis] < centroid[size_t(b)][axis]; });
    const int children = int(g->nodes.size());
    node.index = children;
    node.count = 0;
    g->nodes.emplace_back();
    g->nodes.emplace_back();
    tasks.push_back({children, t.begin, mid});
    tasks.push_back({children + 1, mid, t.end});
  }
  g->tris.resize(size_t(n));
  for (int i = 0; i < n; ++i) {
    const auto& f = F[size_t(order[size_t(i)])];
    g->tris[size_t(i)] = {V[size_t(f[0])], V[size_t(f[1])], V[size_t(f[2])]};
  }
  return g;
}

struct HullEntry {
  std::vector<Eigen::Vector3f> points;  ///< as given, to tell hash collisions apart
  std::shared_ptr<const btConvexShape> shape;
  std::vector<Eigen::Vector3f> vertices;  ///< the hull's own vertices (Bullet's, without its margin)
  Eigen::Vector3d lo, hi;  ///< of the hull as Bullet sees it (margin included), shape frame
};

// Four floats (integers) in one SSE register: the hull's vertices are searched four at a time.
typedef float f4 __attribute__((vector_size(16)));
typedef int32_t i4 __attribute__((vector_size(16)));
constexpr int kHullLanes = 4;

// A query shape, built once per query: the Bullet shape for GJK and its oriented bounding box.
struct Probe {
  const QueryShape* source = nullptr;
  std::shared_ptr<const btConvexShape> shape;
  /// Boxes and convex hulls: the polytope's vertices (shape frame) and the radius it is rounded
  /// by (Bullet's margin around a hull's shrunk vertices; none for a box's exact corners). The
  /// scene's own GJK decides such shapes against triangles; Bullet's only when they penetrate.
  std::shared_ptr<const std::vector<Eigen::Vector3f>> vertices;
  double rounding = 0;
  bool is_sphere = false;
  bool is_box = false;
  double radius = 0;                 ///< sphere
  Eigen::Vector3d obb_center_shape;  ///< the bounding box in the shape frame
  Eigen::Vector3d obb_half;
};

// The probe in one body's frame.
struct Posed {
  Eigen::Matrix3f R;  ///< columns: the box axes in the body frame
  Eigen::Vector3f c;  ///< box centre in the body frame
  Eigen::Vector3f h;  ///< box half extents
  Eigen::Vector3f lo, hi;  ///< axis-aligned box of the oriented one
  Eigen::Vector3d sphere_center;
  btTransform T_body_shape;
  // The last separating axis GJK found (unit, from the shape towards the triangle) and the
  // shape's extent along it: any node or triangle beyond it along the axis is at least that far.
  bool has_axis = false;
  Eigen::Vector3f axis = Eigen::Vector3f::Zero();
  float axis_support = 0;
  // Convex hulls: their vertices in the body frame, x, y and z apart in groups of four (padded
  // with the last vertex), so that the support along a triangle's normal is a few vector steps.
  std::vector<f4> hx, hy, hz;
  double rounding = 0;
  /// Hulls: also prune along each triangle's normal by the vertices (for a box, the oriented-box
  /// test already holds that axis exactly).
  bool prune_by_plane = false;
};

Posed pose_probe(const Probe& p, const Transform& T_body_shape) {
  Posed q;
  q.R = T_body_shape.rotation().cast<float>();
  q.c = (T_body_shape * p.obb_center_shape).cast<float>();
  q.h = p.obb_half.cast<float>();
  const Eigen::Vector3f e = q.R.cwiseAbs() * q.h;
  q.lo = q.c - e;
  q.hi = q.c + e;
  q.sphere_center = T_body_shape.translation();
  q.T_body_shape = to_bt(T_body_shape);
  if (p.vertices) {
    // The hull's own box in the body frame: much tighter than the oriented box's when the hull
    // is long and turned (an arm's link lying across the floor).
    const auto& v = *p.vertices;
    q.rounding = p.rounding;
    q.prune_by_plane = !p.is_box;
    const size_t groups = (v.size() + kHullLanes - 1) / kHullLanes;
    q.hx.resize(groups);
    q.hy.resize(groups);
    q.hz.resize(groups);
    const Eigen::Matrix3f R = T_body_shape.rotation().cast<float>();
    const Eigen::Vector3f t = T_body_shape.translation().cast<float>();
    Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max()), hi = -lo;
    for (size_t i = 0; i < groups * kHullLanes; ++i) {
      const Eigen::Vector3f w = R * v[std::min(i, v.size() - 1)] + t;
      q.hx[i / kHullLanes][i % kHullLanes] = w.x();
      q.hy[i / kHullLanes][i % kHullLanes] = w.y();
      q.hz[i / kHullLanes][i % kHullLanes] = w.z();
      lo = lo.cwiseMin(w);
      hi = hi.cwiseMax(w);
    }
    // The margin, and float rounding of the transformed vertices.
    const float pad = float(q.rounding) + 1e-6f + 1e-6f * std::max(lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff());
    q.lo = q.lo.cwiseMax((lo.array() - pad).matrix());
    q.hi = q.hi.cwiseMin((hi.array() + pad).matrix());
  }
  return q;
}

// The gap between a hull probe and a triangle along the triangle's normal, exact on that axis
// (the hull's vertices projected on it against the triangle's plane), less the shape's margin.
float hull_plane_gap(const Posed& q, const Eigen::Vector3f& a, const Eigen::Vector3f& b, const Eigen::Vector3f& c) {
  Eigen::Vector3f n = (b - a).cross(c - a);
  const float len = n.norm();
  if (!(len > 1e-20f)) return 0.0f;
  n /= len;
  const float d = n.dot(a);
  f4 mn = q.hx[0] * n.x() + q.hy[0] * n.y() + q.hz[0] * n.z(), mx = mn;
  for (size_t i = 1; i < q.hx.size(); ++i) {
    const f4 s = q.hx[i] * n.x() + q.hy[i] * n.y() + q.hz[i] * n.z();
    mn = s < mn ? s : mn;
    mx = s > mx ? s : mx;
  }
  float lo = mn[0], hi = mx[0];
  for (int k = 1; k < kHullLanes; ++k) {
    lo = std::min(lo, mn[k]);
    hi = std::max(hi, mx[k]);
  }
  // Float rounding of the projections must not prune a touching triangle.
  const float slack = float(q.rounding) + 1e-6f + 1e-6f * (std::abs(d) + std::max(std::abs(lo), std::abs(hi)));
  return std::max(lo - d, d - hi) - slack;
}

// Gap between two axis-aligned boxes (0 when they overlap): a lower bound of their distance.
float box_gap(const Eigen::Vector3f& alo, const Eigen::Vector3f& ahi, const Eigen::Vector3f& blo, const Eigen::Vector3f& bhi) {
  const Eigen::Vector3f d = (alo - bhi).cwiseMax(blo - ahi).cwiseMax(0.0f);
  return d.norm();
}

// Lower bound of the distance between the probe's oriented box and an axis-aligned box.
float node_bound(const Posed& q, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  float gap = box_gap(q.lo, q.hi, lo, hi);
  const Eigen::Vector3f nc = 0.5f * (lo + hi), nh = 0.5f * (hi - lo);
  const Eigen::Vector3f d = q.R.transpose() * (nc - q.c);
  const Eigen::Vector3f r = q.R.cwiseAbs().transpose() * nh;
  for (int i = 0; i < 3; ++i) gap = std::max(gap, std::abs(d[i]) - q.h[i] - r[i]);
  if (q.has_axis) gap = std::max(gap, q.axis.dot(nc) - q.axis.cwiseAbs().dot(nh) - q.axis_support);
  return gap;
}

// Lower bound of the distance between the probe's oriented box and a triangle: the largest gap
// over the 13 separating axes (box faces, triangle normal, box edges x triangle edges).
float triangle_bound(const Posed& q, const Geometry::Tri& t) {
  Eigen::Vector3f tlo = t.a.cwiseMin(t.b).cwiseMin(t.c), thi = t.a.cwiseMax(t.b).cwiseMax(t.c);
  float gap = box_gap(q.lo, q.hi, tlo, thi);
  if (q.has_axis) gap = std::max(gap, std::min({q.axis.dot(t.a), q.axis.dot(t.b), q.axis.dot(t.c)}) - q.axis_support);
  const Eigen::Matrix3f Rt = q.R.transpose();
  const Eigen::Vector3f v0 = Rt * (t.a - q.c), v1 = Rt * (t.b - q.c), v2 = Rt * (t.c - q.c);
  const auto& h = q.h;
  // Box faces.
  for (int i = 0; i < 3; ++i) {
    const float mn = std::min({v0[i], v1[i], v2[i]}), mx = std::max({v0[i], v1[i], v2[i]});
    gap = std::max(gap, std::max(mn - h[i], -h[i] - mx));
  }
  const auto axis_gap = [&](const Eigen::Vector3f& a) {
    const float p0 = a.dot(v0), p1 = a.dot(v1), p2 = a.dot(v2);
    const float r = h.dot(a.cwiseAbs());
    const float sep = std::max(std::min({p0, p1, p2}) - r, -r - std::max({p0, p1, p2}));
    if (sep <= 0) return sep;
    const float n = a.norm();
    return n > 1e-12f ? sep / n : 0.0f;
  };
  const Eigen::Vector3f e0 = v1 - v0, e1 = v2 - v1, e2 = v0 - v2;
  gap = std::max(gap, axis_gap(e0.cross(e1)));
  for (const auto* e : {&e0, &e1, &e2}) {
    gap = std::max(gap, axis_gap(Eigen::Vector3f(0, -e->z(), e->y())));
    gap = std::max(gap, axis_gap(Eigen::Vector3f(e->z(), 0, -e->x())));
    gap = std::max(gap, axis_gap(Eigen::Vector3f(-e->y(), e->x(), 0)));
  }
  return gap;
}

// Barycentric weights (of a, b, c) of the point of triangle abc closest to p, by its Voronoi
// regions (Ericson, Real-Time Collision Detection 5.1.5): a vertex or edge region leaves the other
// weights zero.
Eigen::Vector3d closest_weights(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double t = d1 / (d1 - d3);
    return {1 - t, t, 0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double t = d2 / (d2 - d6);
    return {1 - t, 0, t};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - t, t};
  }
  const double denom = 1.0 / (va + vb + vc), v = vb * denom, w = vc * denom;
  return {1 - v - w, v, w};
}

// Signed surface distance between the probe and one triangle, with witnesses in the body frame.
struct Hit {
  double distance = 0;
  Eigen::Vector3d on_shape, on_body;
};

// The support point of a hull probe (its vertices in the body frame, without the margin) along d.
Eigen::Vector3d hull_support(const Posed& q, const Eigen::Vector3d& d) {
  const float dx = float(d.x()), dy = float(d.y()), dz = float(d.z());
  const i4 lanes = {0, 1, 2, 3};
  f4 best = q.hx[0] * dx + q.hy[0] * dy + q.hz[0] * dz;
  i4 index = lanes;
  for (size_t g = 1; g < q.hx.size(); ++g) {
    const f4 s = q.hx[g] * dx + q.hy[g] * dy + q.hz[g] * dz;
    const i4 better = s > best;
    best = better ? s : best;
    index = better ? lanes + int32_t(g * kHullLanes) : index;
  }
  int k = 0;
  for (int j = 1; j < kHullLanes; ++j)
    if (best[j] > best[k]) k = j;
  const size_t i = size_t(index[k]);
  return {q.hx[i / kHullLanes][i % kHullLanes], q.hy[i / kHullLanes][i % kHullLanes], q.hz[i / kHullLanes][i % kHullLanes]};
}

// A simplex of GJK: up to four points w = a - b of the Minkowski difference, with the points a
// (of the shape) and b (of the triangle) that made them, and barycentric weights of the point
// nearest the origin.
struct Simplex {
  std::array<Eigen::Vector3d, 4> w, a, b;
  std::array<double, 4> weight{};
  int n = 0;
  Simplex() {
    w.fill(Eigen::Vector3d::Zero());
    a = b = w;
  }
  /// Adds point i of `from` with weight lambda.
  void take(const Simplex& from, int i, double lambda) {
    w[size_t(n)] = from.w[size_t(i)], a[size_t(n)] = from.a[size_t(i)], b[size_t(n)] = from.b[size_t(i)];
    weight[size_t(n++)] = lambda;
  }
};

// The point of triangle (i, j, k) of `s` nearest the origin; `out` gets the smallest sub-simplex
// that holds it (the points of non-zero weight).
Eigen::Vector3d nearest_on_triangle(const Simplex& s, int i, int j, int k, Simplex& out) {
  const Eigen::Vector3d l = closest_weights(Eigen::Vector3d::Zero(), s.w[size_t(i)], s.w[size_t(j)], s.w[size_t(k)]);
  out.n = 0;
  const int index[3] = {i, j, k};
  for (int m = 0; m < 3; ++m)
    if (l[m] > 0) out.take(s, index[m], l[m]);
  return l[0] * s.w[size_t(i)] + l[1] * s.w[size_t(j)] + l[2] * s.w[size_t(k)];
}

// The point of the simplex nearest the origin; the simplex is reduced to the smallest
// sub-simplex that holds it. Returns false when the origin is inside a tetrahedron.
bool nearest_on_simplex(Simplex& s, Eigen::Vector3d& v) {
  Simplex out;
  switch (s.n) {
    case 1:
      s.weight[0] = 1;
      v = s.w[0];
      return true;
    case 2: {
      const Eigen::Vector3d ab = s.w[1] - s.w[0];
      const double t = -s.w[0].dot(ab), den = ab.squaredNorm();
      const double u = den > 0 ? std::clamp(t / den, 0.0, 1.0) : 0.0;
      if (u < 1) out.take(s, 0, 1 - u);
      if (u > 0) out.take(s, 1, u);
      v = s.w[0] + ab * u;
      break;
    }
    case 3: v = nearest_on_triangle(s, 0, 1, 2, out); break;
    default: {
      // The faces the origin is beyond (on the side away from the fourth vertex); none: inside.
      static constexpr int faces[4][4] = {{0, 1, 2, 3}, {0, 1, 3, 2}, {0, 2, 3, 1}, {1, 2, 3, 0}};
      double best = std::numeric_limits<double>::infinity();
      for (const auto& f : faces) {
        const Eigen::Vector3d& a = s.w[size_t(f[0])];
        const Eigen::Vector3d n = (s.w[size_t(f[1])] - a).cross(s.w[size_t(f[2])] - a);
        if (-n.dot(a) * n.dot(s.w[size_t(f[3])] - a) >= 0) continue;  // the origin is on the fourth vertex's side
        Simplex k;
        const Eigen::Vector3d x = nearest_on_triangle(s, f[0], f[1], f[2], k);
        if (x.squaredNorm() < best) {
          best = x.squaredNorm();
          v = x;
          out = k;
        }
      }
      if (!(best < std::numeric_limits<double>::infinity())) return false;
    }
  }
  s = out;
  return true;
}

// A hull probe against one triangle by GJK (Gilbert, Johnson & Keerthi 1988) on the hull's
// vertices in the body frame, whose support is a short vector loop (Bullet's GJK on the same
// hull costs about four times as much). Decides:
//  - `beyond`: farther than `reach` (surface distance, the shape's margin counted), as soon as
//    the lower bound v . w / |v| (w the support of the difference along -v) exceeds it; the
//    separating direction is kept in q for pruning the next triangles;
//  - `hit`: nearer than `reach`, converged to the distance with its witness points;
//  - `undecided`: penetrating or touching (EPA's job), or not converged.
enum class GjkOutcome { beyond, hit, undecided };

GjkOutcome hull_triangle(Posed& q, const Geometry::Tri& t, double reach, Hit& hit) {
  const Eigen::Vector3d tri[3] = {t.a.cast<double>(), t.b.cast<double>(), t.c.cast<double>()};
  const auto triangle_support = [&](const Eigen::Vector3d& d) -> const Eigen::Vector3d& {
    const double s0 = d.dot(tri[0]), s1 = d.dot(tri[1]), s2 = d.dot(tri[2]);
    return s0 >= s1 && s0 >= s2 ? tri[0] : (s1 >= s2 ? tri[1] : tri[2]);
  };
  // The hull's vertices are floats: a little slack before calling anything beyond reach.
  const double threshold = reach + q.rounding + 1e-6 + 1e-6 * tri[0].cwiseAbs().maxCoeff();
  Simplex s;
  // Start from the last separating direction when there is one (neighbouring triangles share it).
  Eigen::Vector3d d = q.has_axis ? Eigen::Vector3d(-q.axis.cast<double>()) : Eigen::Vector3d(q.c.cast<double>() - tri[0]);
  s.a[0] = hull_support(q, -d);
  s.b[0] = triangle_support(d);
  s.w[0] = s.a[0] - s.b[0];
  s.n = 1;
  Eigen::Vector3d v;
  nearest_on_simplex(s, v);
  for (int iteration = 0; iteration < 64; ++iteration) {
    const double vv = v.squaredNorm();
    if (vv < 1e-14) return GjkOutcome::undecided;  // touching or penetrating
    const Eigen::Vector3d a = hull_support(q, -v), b = triangle_support(v), w = a - b;
    const double vw = v.dot(w), norm = std::sqrt(vv);
    if (vw > threshold * norm) {
      const Eigen::Vector3d axis = -v / norm;  // from the shape towards the triangle
      q.has_axis = true;
      q.axis = axis.cast<float>();
      q.axis_support = float(axis.dot(hull_support(q, axis)) + q.rounding) + 1e-6f;
      return GjkOutcome::beyond;
    }
    // Converged: no support point gets nearer (Bullet's relative tolerance), or w is not new.
    bool repeated = false;
    for (int i = 0; i < s.n; ++i) repeated = repeated || s.w[size_t(i)] == w;
    if (vv - vw <= 1e-6 * vv || repeated) {
      if (norm > threshold) return GjkOutcome::undecided;  // should not happen: the bound said otherwise
      Eigen::Vector3d on_a = Eigen::Vector3d::Zero(), on_b = Eigen::Vector3d::Zero();
      for (int i = 0; i < s.n; ++i) {
        on_a += s.weight[size_t(i)] * s.a[size_t(i)];
        on_b += s.weight[size_t(i)] * s.b[size_t(i)];
      }
      hit.distance = norm - q.rounding;
      hit.on_body = on_b;
      hit.on_shape = on_a - v / norm * q.rounding;
      return hit.distance <= reach ? GjkOutcome::hit : GjkOutcome::beyond;
    }
    s.w[size_t(s.n)] = w, s.a[size_t(s.n)] = a, s.b[size_t(s.n)] = b;
    ++s.n;
    if (!nearest_on_simplex(s, v)) return GjkOutcome::undecided;  // the origin inside: penetrating
  }
  return GjkOutcome::undecided;
}

std::optional<Hit> narrow(const Probe& p, Posed& q, const Geometry::Tri& t, double reach) {
  if (p.is_sphere) {
    const Eigen::Vector3d a = t.a.cast<double>(), b = t.b.cast<double>(), c = t.c.cast<double>();
    const Eigen::Vector3d l = closest_weights(q.sphere_center, a, b, c);
    const Eigen::Vector3d on = l[0] * a + l[1] * b + l[2] * c;
    const Eigen::Vector3d d = q.sphere_center - on;
    const double centre = d.norm();
    if (centre - p.radius > reach) return std::nullopt;
    Eigen::Vector3d n = d / centre;
    if (!(centre > 1e-12)) n = (b - a).cross(c - a).normalized();  // centre on the triangle
    return Hit{centre - p.radius, q.sphere_center - n * p.radius, on};
  }
  if (!q.hx.empty()) {
    Hit hit;
    switch (hull_triangle(q, t, reach, hit)) {
      case GjkOutcome::beyond: return std::nullopt;
      case GjkOutcome::hit: return hit;
      case GjkOutcome::undecided: break;  // penetrating: Bullet's GJK and EPA
    }
  }
  btTriangleShape tri(to_bt(t.a), to_bt(t.b), to_bt(t.c));
  tri.setMargin(0);
  btVoronoiSimplexSolver simplex;
  btGjkEpaPenetrationDepthSolver epa;
  btGjkPairDetector gjk(p.shape.get(), &tri, &simplex, &epa);
  // Warm start: the last separating direction (from the triangle towards the shape; Bullet's
  // axis points from B to A) is usually close for the next triangle, and saves GJK iterations.
  if (q.has_axis) gjk.setCachedSeparatingAxis(btVector3(-q.axis.x(), -q.axis.y(), -q.axis.z()));
  btGjkPairDetector::ClosestPointInput in;
  in.m_transformA = q.T_body_shape;
  in.m_transformB.setIdentity();
  btPointCollector out;
  gjk.getClosestPoints(in, out, nullptr);
  if (out.m_hasResult && out.m_distance > 0) {
    // Keep the separating axis: neighbouring triangles are mostly beyond it too.
    const btVector3 d = -out.m_normalOnBInWorld;
    const btVector3 local = q.T_body_shape.getBasis().transpose() * d;
    const btVector3 support = q.T_body_shape * p.shape->localGetSupportingVertex(local);
    q.has_axis = true;
    q.axis = Eigen::Vector3f(d.x(), d.y(), d.z());
    q.axis_support = float(d.dot(support)) + 1e-6f;  // float rounding must not prune a touching triangle
  }
  if (!out.m_hasResult || out.m_distance > reach) return std::nullopt;
  const Eigen::Vector3d on_body = to_eigen(out.m_pointInWorld);
  return Hit{double(out.m_distance), on_body + to_eigen(out.m_normalOnBInWorld) * double(out.m_distance), on_body};
}

// Walks the tree: `reach()` is read again after every triangle (distance queries shrink it);
// `visit(tri)` returns false to stop. `nearest_first` orders children by their lower bound.
template <typename Reach, typename Visit>
void traverse(const Geometry& g, Posed& q, bool nearest_first, Reach&& reach, Visit&& visit) {
  std::array<int32_t, 128> stack{};
  int top = 0;
  if (node_bound(q, g.nodes[0].lo, g.nodes[0].hi) > reach()) return;
  stack[size_t(top++)] = 0;
  while (top > 0) {
    const auto& node = g.nodes[size_t(stack[size_t(--top)])];
    if (node.count > 0) {
      for (int i = node.index; i < node.index + node.count; ++i) {
        const auto& t = g.tris[size_t(i)];
        if (triangle_bound(q, t) > reach()) continue;
        if (q.prune_by_plane && hull_plane_gap(q, t.a, t.b, t.c) > reach()) continue;
        if (!visit(t)) return;
      }
      continue;
    }
    const int a = node.index, b = node.index + 1;
    const float r = reach();
    const float ga = node_bound(q, g.nodes[size_t(a)].lo, g.nodes[size_t(a)].hi);
    const float gb = node_bound(q, g.nodes[size_t(b)].lo, g.nodes[size_t(b)].hi);
    // Push the farther first so the nearer is visited first.
    const bool a_first = !nearest_first || ga <= gb;
    const int first = a_first ? a : b, second = a_first ? b : a;
    const float gfirst = a_first ? ga : gb, gsecond = a_first ? gb : ga;
    if (gsecond <= r) stack[size_t(top++)] = second;
    if (gfirst <= r) stack[size_t(top++)] = first;
  }
}

uint64_t hash_points(const std::vector<Eigen::Vector3f>& points) {
  uint64_t h = 1469598103934665603ull ^ points.size();
  for (const auto& p : points)
    for (int k = 0; k < 3; ++k) {
      uint32_t w = 0;
      std::memcpy(&w, &p[k], sizeof w);
      h = (h ^ w) * 1099511628211ull;
    }
  return h;
}

bool allowed(const std::vector<AllowedPair>& pairs, const std::string& shape, int64_t body) {
  return std::any_of(pairs.begin(), pairs.end(), [&](const AllowedPair& p) {
    return (p.shape == "*" || p.shape == shape) && (p.body < 0 || p.body == body);
  });
}

// Ray against a triangle (Moeller-Trumbore): the ray parameter, or a negative number.
double ray_triangle(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Geometry::Tri& t) {
  const Eigen::Vector3d a = t.a.cast<double>(), e1 = t.b.cast<double>() - a, e2 = t.c.cast<double>() - a;
  const Eigen::Vector3d p = d.cross(e2);
  const double det = e1.dot(p);
  if (std::abs(det) < 1e-18) return -1;
  const double inv = 1.0 / det;
  const Eigen::Vector3d s = o - a;
  const double u = s.dot(p) * inv;
  if (u < 0 || u > 1) return -1;
  const Eigen::Vector3d qv = s.cross(e1);
  const double v = d.dot(qv) * inv;
  if (v < 0 || u + v > 1) return -1;
  return e2.dot(qv) * inv;
}

struct Body {
  int64_t id = 0;
  std::shared_ptr<const Geometry> geometry;
  Transform T_world_body = Transform::Identity();
  Transform T_body_world = Transform::Identity();
  Eigen::Vector3f lo, hi;  ///< world-frame bounding box
  double margin_m = 0.0;
};

}  // namespace

struct CollisionScene::Impl {
  std::map<int64_t, Body> bodies;
  std::map<const TriangleMesh*, std::weak_ptr<const Geometry>> entries;
  mutable std::mutex hulls_mutex;
  mutable std::unordered_map<uint64_t, std::shared_ptr<const HullEntry>> hulls;

  std::shared_ptr<const Geometry> entry_for(std::shared_ptr<const TriangleMesh> mesh) {
    if (auto it = entries.find(mesh.get()); it != entries.end())
      if (auto e = it->second.lock()) return e;
    const TriangleMesh* key = mesh.get();
    std::shared_ptr<const Geometry> g = build(std::move(mesh));
    entries[key] = g;
    return g;
  }

  static void place(Body& b, const Transform& T_world_body) {
    b.T_world_body = T_world_body;
    b.T_body_world = T_world_body.inverse(Eigen::Isometry);
    const auto& root = b.geometry->nodes[0];
    const Eigen::Matrix3f R = T_world_body.rotation().cast<float>();
    const Eigen::Vector3f c = T_world_body.cast<float>() * (0.5f * (root.lo + root.hi));
    const Eigen::Vector3f e = R.cwiseAbs() * (0.5f * (root.hi - root.lo));
    b.lo = c - e;
    b.hi = c + e;
  }

  // A hull's Bullet shape, computed once per distinct point set (a robot's links come back with
  // every query).
  std::shared_ptr<const HullEntry> hull_for(const QueryShape& s) const {
    const uint64_t key = hash_points(s.points);
    {
      std::lock_guard<std::mutex> lock(hulls_mutex);
      if (auto it = hulls.find(key); it != hulls.end() && it->second->points == s.points) return it->second;
    }
    auto e = std::make_shared<HullEntry>();
    e->points = s.points;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const auto& p : s.points) centroid += p.cast<double>();
    centroid /= double(s.points.size());
    auto hull = std::make_shared<btConvexHullShape>();
    for (const auto& p : s.points) {
      // Bullet adds a hull's margin outside it: pull the points in by as much.
      Eigen::Vector3d q = p.cast<double>();
      const Eigen::Vector3d d = q - centroid;
      const double n = d.norm();
      if (n > kShapeMargin) q -= d / n * kShapeMargin;
      hull->addPoint(btVector3(q.x(), q.y(), q.z()), false);
    }
    hull->recalcLocalAabb();
    hull->optimizeConvexHull();
    hull->setMargin(kShapeMargin);
    e->lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::max());
    e->hi = -e->lo;
    for (int i = 0; i < hull->getNumPoints(); ++i) {
      const Eigen::Vector3d v = to_eigen(hull->getUnscaledPoints()[i]);
      e->vertices.push_back(v.cast<float>());
      e->lo = e->lo.cwiseMin(v);
      e->hi = e->hi.cwiseMax(v);
    }
    e->lo.array() -= kShapeMargin;
    e->hi.array() += kShapeMargin;
    e->shape = std::move(hull);
    std::lock_guard<std::mutex> lock(hulls_mutex);
    if (hulls.size() > 4096) hulls.clear();
    hulls[key] = e;
    return e;
  }

  Probe make_probe(const QueryShape& s) const {
    const auto bad = [&](const std::string& what) { return Error("query shape '" + s.name + "': " + what); };
    if (!finite_pose(s.T_world_shape)) throw bad("pose is not finite");
    Probe p;
    p.source = &s;
    p.obb_center_shape = Eigen::Vector3d::Zero();
    std::shared_ptr<btConvexShape> shape;
    switch (s.kind) {
      case QueryShape::Kind::box:
        if (!(s.size.allFinite() && s.size.minCoeff() > 0)) throw bad("box size must be positive");
        shape = std::make_shared<btBoxShape>(btVector3(s.size.x() / 2, s.size.y() / 2, s.size.z() / 2));
        p.obb_half = s.size / 2;
        p.is_box = true;
        {
          auto corners = std::make_shared<std::vector<Eigen::Vector3f>>();
          for (int i = 0; i < 8; ++i)
            corners->emplace_back(float((i & 1 ? 0.5 : -0.5) * s.size.x()), float((i & 2 ? 0.5 : -0.5) * s.size.y()),
                                  float((i & 4 ? 0.5 : -0.5) * s.size.z()));
          p.vertices = std::move(corners);
        }
        break;
      case QueryShape::Kind::sphere:
        if (!(std::isfinite(s.radius_m) && s.radius_m > 0)) throw bad("sphere radius must be positive");
        p.is_sphere = true;
        p.radius = s.radius_m;
        p.obb_half = Eigen::Vector3d::Constant(s.radius_m);
        return p;
      case QueryShape::Kind::cylinder:
        if (!(std::isfinite(s.radius_m) && s.radius_m > 0 && std::isfinite(s.length_m) && s.length_m > 0))
          throw bad("cylinder radius and length must be positive");
        shape = std::make_shared<btCylinderShapeZ>(btVector3(s.radius_m, s.radius_m, s.length_m / 2));
        p.obb_half = Eigen::Vector3d(s.radius_m, s.radius_m, s.length_m / 2);
        break;
      case QueryShape::Kind::capsule: {
        if (!(std::isfinite(s.radius_m) && s.radius_m > 0 && std::isfinite(s.length_m) && s.length_m >= 0))
          throw bad("capsule radius must be positive and length not negative");
        auto capsule = std::make_shared<btCapsuleShapeZ>(s.radius_m, s.length_m);
        p.obb_half = Eigen::Vector3d(s.radius_m, s.radius_m, s.length_m / 2 + s.radius_m);
        p.shape = std::move(capsule);  // a capsule is all margin: keep Bullet's
        p.obb_half.array() += 1e-6;
        return p;
      }
      case QueryShape::Kind::convex_hull: {
        if (s.points.size() < 4) throw bad("a convex hull needs at least 4 points");
        for (const auto& q : s.points)
          if (!q.allFinite()) throw bad("hull point is not finite");
        const auto hull = hull_for(s);
        p.shape = hull->shape;
        p.vertices = std::shared_ptr<const std::vector<Eigen::Vector3f>>(hull, &hull->vertices);
        p.rounding = kShapeMargin;
        p.obb_center_shape = 0.5 * (hull->lo + hull->hi);
        p.obb_half = 0.5 * (hull->hi - hull->lo);
        p.obb_half.array() += 1e-6;
        return p;
      }
    }
    shape->setMargin(kShapeMargin);
    p.shape = std::move(shape);
    p.obb_half.array() += 1e-6;  // float rounding of the bounds must not prune a touching triangle
    return p;
  }

  // World-frame bounding box of a probe.
  static void world_box(const Probe& p, Eigen::Vector3f& lo, Eigen::Vector3f& hi) {
    const auto& T = p.source->T_world_shape;
    const Eigen::Vector3d c = T * p.obb_center_shape;
    const Eigen::Vector3d e = T.rotation().cwiseAbs() * p.obb_half;
    lo = (c - e).cast<float>();
    hi = (c + e).cast<float>();
  }

  static Contact to_world(const std::string& shape, const Body& b, const Hit& h) {
    return Contact{shape, b.id, b.T_world_body * h.on_shape, b.T_world_body * h.on_body, h.distance - b.margin_m};
  }
};

CollisionScene::CollisionScene() : impl_(std::make_unique<Impl>()) {}

CollisionScene::~CollisionScene() = default;

std::shared_ptr<const BodyGeometry> CollisionScene::build_geometry(std::shared_ptr<const TriangleMesh> mesh) {
  if (!mesh) throw Error("collision scene: a body has no mesh");
  return build(std::move(mesh));
}

void CollisionScene::set_body(int64_t id, std::shared_ptr<const TriangleMesh> mesh, const Transform& T_world_body, double margin_m) {
  if (!mesh) throw Error("collision scene: body " + std::to_string(id) + " has no mesh");
  if (!finite_pose(T_world_body)) throw Error("collision scene: body " + std::to_string(id) + " has a non-finite pose");
  set_body(id, impl_->entry_for(std::move(mesh)), T_world_body, margin_m);
}

void CollisionScene::set_body(int64_t id, std::shared_ptr<const BodyGeometry> geometry, const Transform& T_world_body, double margin_m) {
  if (!geometry) throw Error("collision scene: body " + std::to_string(id) + " has no geometry");
  if (!finite_pose(T_world_body)) throw Error("collision scene: body " + std::to_string(id) + " has a non-finite pose");
  if (!(std::isfinite(margin_m) && margin_m >= 0))
    throw Error("collision scene: body " + std::to_string(id) + " has a negative or non-finite margin");
  impl_->entries[geometry->mesh.get()] = geometry;  // reused when the same mesh comes again
  Body body;
  body.id = id;
  body.geometry = std::move(geometry);
  body.margin_m = margin_m;
  Impl::place(body, T_world_body);
  impl_->bodies[id] = std::move(body);
}

void CollisionScene::set_pose(int64_t id, const Transform& T_world_body) {
  auto it = impl_->bodies.find(id);
  if (it == impl_->bodies.end()) throw Error("collision scene: no body " + std::to_string(id));
  if (!finite_pose(T_world_body)) throw Error("collision scene: body " + std::to_string(id) + " has a non-finite pose");
  Impl::place(it->second, T_world_body);
}

bool CollisionScene::remove(int64_t id) { return impl_->bodies.erase(id) > 0; }

bool CollisionScene::contains(int64_t id) const { return impl_->bodies.count(id) > 0; }

std::shared_ptr<const BodyGeometry> CollisionScene::geometry(int64_t id) const {
  const auto it = impl_->bodies.find(id);
  return it == impl_->bodies.end() ? nullptr : it->second.geometry;
}

std::vector<int64_t> CollisionScene::bodies() const {
  std::vector<int64_t> ids;
  for (const auto& [id, body] : impl_->bodies) ids.push_back(id);
  return ids;
}

size_t CollisionScene::triangle_count() const {
  size_t n = 0;
  for (const auto& [id, body] : impl_->bodies) n += body.geometry->tris.size();
  return n;
}

CollisionResult CollisionScene::check(const std::vector<QueryShape>& shapes, const std::vector<AllowedPair>& allowed_pairs,
                                      const CheckOptions& options) const {
  std::vector<Probe> probes;
  probes.reserve(shapes.size());
  for (const auto& s : shapes) probes.push_back(impl_->make_probe(s));  // all validated before any work
  CollisionResult result;
  for (const auto& p : probes) {
    Eigen::Vector3f lo, hi;
    Impl::world_box(p, lo, hi);
    for (const auto& [id, body] : impl_->bodies) {
      if (box_gap(lo, hi, body.lo, body.hi) > float(body.margin_m)) continue;
      if (allowed(allowed_pairs, p.source->name, body.id)) continue;
      Posed q = pose_probe(p, body.T_body_world * p.source->T_world_shape);
      const double reach = body.margin_m;
      std::optional<Hit> best;
      traverse(*body.geometry, q, false, [&] { return float(reach); }, [&](const BodyGeometry::Tri& t) {
        const auto h = narrow(p, q, t, reach);
        if (!h) return true;
        if (!best || h->distance < best->distance) best = h;
        return options.deepest_contacts;
      });
      if (!best) continue;
      result.in_collision = true;
      result.contacts.push_back(Impl::to_world(p.source->name, body, *best));
      if (options.stop_at_first) return result;
    }
  }
  return result;
}

DistanceResult CollisionScene::distance(const std::vector<QueryShape>& shapes, double max_distance_m,
                                        const std::vector<AllowedPair>& allowed_pairs) const {
  if (!(std::isfinite(max_distance_m) && max_distance_m > 0)) throw Error("distance query: max distance must be positive");
  std::vector<Probe> probes;
  probes.reserve(shapes.size());
  for (const auto& s : shapes) probes.push_back(impl_->make_probe(s));
  DistanceResult result;
  result.distance_m = max_distance_m;
  for (const auto& p : probes) {
    Eigen::Vector3f lo, hi;
    Impl::world_box(p, lo, hi);
    // Nearer bodies first, so the reach shrinks early.
    std::vector<std::pair<float, const Body*>> near;
    for (const auto& [id, body] : impl_->bodies) {
      const float gap = box_gap(lo, hi, body.lo, body.hi);
      if (gap - body.margin_m > max_distance_m || allowed(allowed_pairs, p.source->name, body.id)) continue;
      near.emplace_back(gap - float(body.margin_m), &body);
    }
    std::sort(near.begin(), near.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [gap, body] : near) {
      if (gap > result.distance_m) break;
      Posed q = pose_probe(p, body->T_body_world * p.source->T_world_shape);
      // Only triangles nearer than the best so far can improve it (raw surface distance).
      const auto reach = [&] { return result.distance_m + body->margin_m; };
      traverse(*body->geometry, q, true, [&] { return float(reach()); }, [&](const BodyGeometry::Tri& t) {
        const auto h = narrow(p, q, t, reach());
        if (h && h->distance - body->margin_m < result.distance_m) {
          result.distance_m = h->distance - body->margin_m;
          result.closest = Impl::to_world(p.source->name, *body, *h);
        }
        return result.distance_m >= 0;
      });
      if (result.distance_m < 0) return result;  // in collision: see the header
    }
  }
  return result;
}

RayHit CollisionScene::raycast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_range_m) const {
  if (!origin.allFinite() || !direction.allFinite() || direction.norm() == 0)
    throw Error("ray cast: the origin and direction must be finite and the direction non-zero");
  if (!(std::isfinite(max_range_m) && max_range_m > 0)) throw Error("ray cast: max range must be positive");
  const Eigen::Vector3d dir_world = direction.normalized();
  RayHit hit;
  double best = max_range_m;
  for (const auto& [id, body] : impl_->bodies) {
    const Eigen::Vector3d o = body.T_body_world * origin, d = body.T_body_world.linear() * dir_world;
    const Eigen::Vector3d inv = d.cwiseInverse();
    const auto slab = [&](const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
      double t0 = 0, t1 = best;
      for (int k = 0; k < 3; ++k) {
        double a = (double(lo[k]) - o[k]) * inv[k], b = (double(hi[k]) - o[k]) * inv[k];
        if (a > b) std::swap(a, b);
        if (std::isnan(a)) a = -std::numeric_limits<double>::infinity();  // parallel, origin on the slab
        if (std::isnan(b)) b = std::numeric_limits<double>::infinity();
        t0 = std::max(t0, a);
        t1 = std::min(t1, b);
      }
      return t0 <= t1 + 1e-9;
    };
    const auto& g = *body.geometry;
    std::array<int32_t, 128> stack{};
    int top = 0;
    if (slab(g.nodes[0].lo, g.nodes[0].hi)) stack[size_t(top++)] = 0;
    while (top > 0) {
      const auto& node = g.nodes[size_t(stack[size_t(--top)])];
      if (!slab(node.lo, node.hi)) continue;
      if (node.count == 0) {
        stack[size_t(top++)] = node.index;
        stack[size_t(top++)] = node.index + 1;
        continue;
      }
      for (int i = node.index; i < node.index + node.count; ++i) {
        const auto& t = g.tris[size_t(i)];
        const double s = ray_triangle(o, d, t);
        if (s < 0 || s > best) continue;
        best = s;
        Eigen::Vector3d n = (t.b - t.a).cross(t.c - t.a).cast<double>().normalized();
        if (n.dot(d) > 0) n = -n;  // facing the ray's origin
        hit.hit = true;
        hit.body = id;
        hit.distance_m = s;
        hit.point = body.T_world_body * (o + d * s);
        hit.normal = body.T_world_body.linear() * n;
      }
    }
  }
  return hit;
}

}  // namespace artisan::worldmodel
