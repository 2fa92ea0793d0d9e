// Collision scene: analytic cases (sphere/plane, box/box, rays) and brute force on a real mesh.
#include <gtest/gtest.h>

#include <random>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_io.hpp"
#include "artisan/worldmodel/collision_scene.hpp"
#include "test_support.hpp"

namespace artisan::worldmodel {
namespace {

// A square in the z = 0 plane, `half` on each side of the origin, facing +z.
std::shared_ptr<TriangleMesh> plane(float half) {
  auto m = std::make_shared<TriangleMesh>();
  m->vertices = {{-half, -half, 0}, {half, -half, 0}, {half, half, 0}, {-half, half, 0}};
  m->faces = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

// An axis-aligned box mesh of full size `s` centred at the origin.
std::shared_ptr<TriangleMesh> box_mesh(const Eigen::Vector3f& s) {
  auto m = std::make_shared<TriangleMesh>();
  for (int i = 0; i < 8; ++i)
    m->vertices.emplace_back((i & 1 ? 0.5f : -0.5f) * s.x(), (i & 2 ? 0.5f : -0.5f) * s.y(), (i & 4 ? 0.5f : -0.5f) * s.z());
  m->faces = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
              {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

QueryShape sphere_at(const Eigen::Vector3d& c, double r, const std::string& name = "sphere") {
  QueryShape s;
  s.name = name;
  s.kind = QueryShape::Kind::sphere;
  s.radius_m = r;
  s.T_world_shape = Transform(Eigen::Translation3d(c));
  return s;
}

QueryShape box_at(const Transform& T, const Eigen::Vector3d& size, const std::string& name = "box") {
  QueryShape s;
  s.name = name;
  s.kind = QueryShape::Kind::box;
  s.size = size;
  s.T_world_shape = T;
  return s;
}

TEST(CollisionScene, SphereAgainstPlane) {
  CollisionScene scene;
  scene.set_body(7, plane(1.0f), Transform::Identity());
  for (double h : {0.5, 0.2, 0.11, 0.09, 0.0, -0.05}) {
    const auto c = scene.check({sphere_at({0.1, -0.2, h}, 0.1)});
    EXPECT_EQ(c.in_collision, h <= 0.1) << h;
    if (c.in_collision) {
      ASSERT_EQ(c.contacts.size(), 1u);
      EXPECT_EQ(c.contacts[0].body, 7);
      EXPECT_NEAR(c.contacts[0].distance_m, std::abs(h) - 0.1, 1e-4) << h;
    }
  }
  const auto d = scene.distance({sphere_at({0.3, 0.3, 0.25}, 0.1)}, 1.0);
  ASSERT_TRUE(d.closest);
  EXPECT_NEAR(d.distance_m, 0.15, 1e-4);
  EXPECT_NEAR(d.closest->point_on_body.z(), 0.0, 1e-4);
  EXPECT_NEAR(d.closest->point_on_body.x(), 0.3, 1e-4);
  EXPECT_NEAR(d.closest->point_on_shape.z(), 0.15, 1e-4);
  // Nothing within reach: the reach itself, no witness.
  const auto far = scene.distance({sphere_at({0, 0, 2.0}, 0.1)}, 0.5);
  EXPECT_FALSE(far.closest);
  EXPECT_EQ(far.distance_m, 0.5);
}

TEST(CollisionScene, BoxAgainstBoxWithMarginAndRotation) {
  CollisionScene scene;
  scene.set_body(1, box_mesh({0.2f, 0.2f, 0.2f}), Transform(Eigen::Translation3d(1, 0, 0)), 0.01);
  // Face to face, 5 cm apart: distance 0.05 less the 1 cm margin.
  const Transform T(Eigen::Translation3d(1 - 0.1 - 0.05 - 0.05, 0, 0));
  const auto d = scene.distance({box_at(T, {0.1, 0.1, 0.1})}, 1.0);
  EXPECT_NEAR(d.distance_m, 0.04, 2e-4);
  EXPECT_FALSE(scene.check({box_at(T, {0.1, 0.1, 0.1})}).in_collision);
  // 5 mm apart: inside the margin, so in collision.
  const Transform near(Eigen::Translation3d(1 - 0.1 - 0.005 - 0.05, 0, 0));
  EXPECT_TRUE(scene.check({box_at(near, {0.1, 0.1, 0.1})}).in_collision);
  // A box turned 45° about z presents its edge: half diagonal 0.0707.
  Transform R = Transform(Eigen::Translation3d(1 - 0.1 - 0.1, 0, 0)) * Eigen::AngleAxisd(M_PI / 4, Eigen::Vector3d::UnitZ());
  EXPECT_NEAR(scene.distance({box_at(R, {0.1, 0.1, 0.1})}, 1.0).distance_m, 0.1 - 0.05 * std::sqrt(2.0) - 0.01, 3e-4);
}

TEST(CollisionScene, AllowedPairsAndRemoval) {
  CollisionScene scene;
  scene.set_body(1, plane(1.0f), Transform::Identity());
  scene.set_body(2, box_mesh({0.1f, 0.1f, 0.1f}), Transform(Eigen::Translation3d(0, 0, 0.05)));
  const auto gripper = sphere_at({0, 0, 0.12}, 0.03, "gripper");
  EXPECT_TRUE(scene.check({gripper}).in_collision);  // touches the box (top at 0.10)
  EXPECT_FALSE(scene.check({gripper}, {{"gripper", 2}}).in_collision);
  EXPECT_TRUE(scene.check({sphere_at({0, 0, 0.02}, 0.03, "gripper")}, {{"gripper", 2}}).in_collision);  // the plane still counts
  EXPECT_FALSE(scene.check({gripper}, {{"*", -1}}).in_collision);
  EXPECT_TRUE(scene.remove(2));
  EXPECT_FALSE(scene.remove(2));
  EXPECT_FALSE(scene.check({gripper}).in_collision);
  // Moving a body needs no rebuild.
  scene.set_pose(1, Transform(Eigen::Translation3d(0, 0, 0.1)));
  EXPECT_TRUE(scene.check({gripper}).in_collision);
  EXPECT_THROW(scene.set_pose(99, Transform::Identity()), Error);
}

TEST(CollisionScene, RayCast) {
  CollisionScene scene;
  scene.set_body(3, plane(1.0f), Transform(Eigen::Translation3d(0, 0, -1)));
  const auto hit = scene.raycast({0.2, 0.1, 1}, {0, 0, -2}, 5);
  ASSERT_TRUE(hit.hit);
  EXPECT_EQ(hit.body, 3);
  EXPECT_NEAR(hit.distance_m, 2.0, 1e-5);
  EXPECT_NEAR(hit.point.z(), -1.0, 1e-5);
  EXPECT_NEAR(std::abs(hit.normal.z()), 1.0, 1e-5);
  EXPECT_FALSE(scene.raycast({0.2, 0.1, 1}, {0, 0, -1}, 1.5).hit);
  EXPECT_FALSE(scene.raycast({0.2, 0.1, 1}, {0, 0, 1}, 5).hit);
}

TEST(CollisionScene, BadInputIsRefused) {
  CollisionScene scene;
  EXPECT_THROW(scene.set_body(1, std::make_shared<TriangleMesh>(), Transform::Identity()), Error);
  auto nan_mesh = plane(1.0f);
  nan_mesh->vertices[0].x() = NAN;
  EXPECT_THROW(scene.set_body(1, nan_mesh, Transform::Identity()), Error);
  scene.set_body(1, plane(1.0f), Transform::Identity());
  EXPECT_THROW(scene.check({sphere_at({0, 0, NAN}, 0.1)}), Error);
  EXPECT_THROW(scene.check({sphere_at({0, 0, 0}, -0.1)}), Error);
  EXPECT_THROW(scene.check({box_at(Transform::Identity(), {0.1, 0, 0.1})}), Error);
  QueryShape hull;
  hull.kind = QueryShape::Kind::convex_hull;
  hull.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  EXPECT_THROW(scene.check({hull}), Error);
  EXPECT_THROW(scene.distance({sphere_at({0, 0, 1}, 0.1)}, 0.0), Error);
  EXPECT_THROW(scene.raycast({0, 0, 0}, {0, 0, 0}, 1), Error);
}

// Exact distance from a point to a triangle (Ericson, Real-Time Collision Detection 5.1.5).
double point_triangle_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return (p - a).norm();
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return (p - b).norm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (p - (a + ab * (d1 / (d1 - d3)))).norm();
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return (p - c).norm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (p - (a + ac * (d2 / (d2 - d6)))).norm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return (p - (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))))).norm();
  const double denom = 1.0 / (va + vb + vc);
  return (p - (a + ab * (vb * denom) + ac * (vc * denom))).norm();
}

TEST(CollisionScene, DistanceMatchesBruteForceOnTheBunny) {
  auto bunny = std::make_shared<TriangleMesh>(io::read_mesh(test::bunny_dir() / "reconstruction" / "bun_zipper.ply"));
  const Transform T_world_bunny = Transform(Eigen::Translation3d(0.5, -0.2, 0.1)) * Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized());
  CollisionScene scene;
  scene.set_body(5, bunny, T_world_bunny);
  std::mt19937 rng(11);
  const Eigen::AlignedBox3f box = bunny->bounds();
  std::uniform_real_distribution<double> u(-0.08, 0.08);
  int checked = 0, collisions = 0;
  for (int k = 0; k < 40; ++k) {
    const Eigen::Vector3d c_bunny = box.center().cast<double>() + Eigen::Vector3d(u(rng), u(rng), u(rng));
    const double r = 0.01;
    double best = 1e9;
    for (const auto& f : bunny->faces)
      best = std::min(best, point_triangle_distance(c_bunny, bunny->vertices[f[0]].cast<double>(), bunny->vertices[f[1]].cast<double>(),
                                                    bunny->vertices[f[2]].cast<double>()));
    const auto s = sphere_at(T_world_bunny * c_bunny, r);
    const auto d = scene.distance({s}, 0.2);
    if (best - r > 0.002) {  // clear of the surface: exact distance
      ASSERT_TRUE(d.closest) << k;
      EXPECT_NEAR(d.distance_m, best - r, 1e-4) << k;
      EXPECT_FALSE(scene.check({s}).in_collision) << k;
      ++checked;
    } else if (best < r - 0.002) {
      EXPECT_TRUE(scene.check({s}).in_collision) << k;
      ++collisions;
    }
  }
  EXPECT_GE(checked, 10);
  EXPECT_GE(collisions, 3);
}

// Method: the same queries against the bunny as one body (hierarchy, separating-axis and distance
// pruning, first-contact early exit) and as one body per triangle (nothing to prune but each
// triangle's own bounds): pruning must never change an answer. Boxes, cylinders and convex hulls
// (random points in an ellipsoid, as a robot link), with and without a margin.
TEST(CollisionScene, PruningNeverChangesTheAnswer) {
  const auto bunny = io::read_mesh(test::bunny_dir() / "reconstruction" / "bun_zipper.ply");
  const Transform T_world_bunny = Transform(Eigen::Translation3d(0.1, 0.2, -0.1)) * Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 0, 1).normalized());
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  // The triangles near the bunny's middle, one body each (ID = 1000 + index), and all of them as one.
  const Eigen::Vector3f centre = bunny.bounds().center();
  auto part = std::make_shared<TriangleMesh>();
  part->vertices = bunny.vertices;
  for (const auto& f : bunny.faces)
    if ((bunny.vertices[size_t(f[0])] - centre).norm() < 0.045f) part->faces.push_back(f);
  ASSERT_GT(part->faces.size(), 3000u);
  for (double margin : {0.0, 0.003}) {
    CollisionScene whole, each;
    whole.set_body(1, part, T_world_bunny, margin);
    for (size_t i = 0; i < part->faces.size(); ++i) {
      auto t = std::make_shared<TriangleMesh>();
      for (int k = 0; k < 3; ++k) t->vertices.push_back(part->vertices[size_t(part->faces[i][k])]);
      t->faces = {{0, 1, 2}};
      each.set_body(int64_t(1000 + i), t, T_world_bunny, margin);
    }
    std::vector<Eigen::Vector3f> hull_points;
    for (int i = 0; i < 60; ++i) hull_points.emplace_back(float(0.02 * u(rng)), float(0.015 * u(rng)), float(0.05 * u(rng)));
    int collisions = 0, free = 0;
    for (int k = 0; k < 60; ++k) {
      QueryShape s;
      s.name = "probe";
      s.kind = k % 3 == 0 ? QueryShape::Kind::box : k % 3 == 1 ? QueryShape::Kind::cylinder : QueryShape::Kind::convex_hull;
      s.size = {0.03, 0.02, 0.05};
      s.radius_m = 0.012;
      s.length_m = 0.04;
      s.points = hull_points;
      s.T_world_shape = T_world_bunny * Transform(Eigen::Translation3d(centre.cast<double>() + 0.05 * Eigen::Vector3d(u(rng), u(rng), u(rng)))) *
                        Eigen::AngleAxisd(M_PI * u(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized());
      const auto a = whole.check({s});
      const auto b = each.check({s}, {}, CheckOptions{.deepest_contacts = false, .stop_at_first = true});
      ASSERT_EQ(a.in_collision, b.in_collision) << k << " margin " << margin;
      (a.in_collision ? collisions : free)++;
      if (a.in_collision) {
        ASSERT_EQ(a.contacts.size(), 1u);
        EXPECT_LE(a.contacts[0].distance_m, 1e-9);
        // The deepest contact over the body equals the deepest over the triangles.
        const auto deep = whole.check({s}, {}, CheckOptions{.deepest_contacts = true, .stop_at_first = false});
        double deepest = 1e9;
        for (const auto& c : each.check({s}).contacts) deepest = std::min(deepest, c.distance_m);
        EXPECT_NEAR(deep.contacts[0].distance_m, deepest, 1e-6) << k;
      }
      const auto da = whole.distance({s}, 0.05), db = each.distance({s}, 0.05);
      // In collision, distance() stops at the first penetration it finds: only the sign compares.
      if (a.in_collision) EXPECT_LT(da.distance_m, 1e-9) << k;
      else EXPECT_NEAR(da.distance_m, db.distance_m, 1e-6) << k << " margin " << margin;
      if (da.closest) {
        // Witnesses: as far apart as the distance (plus the margin), in the world frame.
        EXPECT_NEAR((da.closest->point_on_shape - da.closest->point_on_body).norm(), std::abs(da.distance_m + margin), 2e-4) << k;
      }
    }
    EXPECT_GE(collisions, 10);
    EXPECT_GE(free, 10);
  }
}

TEST(CollisionScene, StopAtFirstReportsOneContact) {
  CollisionScene scene;
  scene.set_body(1, plane(1.0f), Transform::Identity());
  scene.set_body(2, plane(1.0f), Transform(Eigen::Translation3d(0, 0, 0.01)));
  const auto s = sphere_at({0, 0, 0.005}, 0.02);
  EXPECT_EQ(scene.check({s}).contacts.size(), 2u);
  const auto first = scene.check({s}, {}, CheckOptions{.deepest_contacts = false, .stop_at_first = true});
  EXPECT_TRUE(first.in_collision);
  EXPECT_EQ(first.contacts.size(), 1u);
}

// Closest distance between segments p1q1 and p2q2 (Ericson, Real-Time Collision Detection 5.1.9).
double segment_distance(const Eigen::Vector3d& p1, const Eigen::Vector3d& q1, const Eigen::Vector3d& p2, const Eigen::Vector3d& q2) {
  const Eigen::Vector3d d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r), c = d1.dot(r), b = d1.dot(d2);
  const double denom = a * e - b * b;
  double s = denom > 1e-20 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
  double t = (b * s + f) / e;
  if (t < 0) t = 0, s = std::clamp(-c / a, 0.0, 1.0);
  else if (t > 1) t = 1, s = std::clamp((b - c) / a, 0.0, 1.0);
  return ((p1 + d1 * s) - (p2 + d2 * t)).norm();
}

// Exact distance between a box (half extents h, in its frame) and a triangle (in the box frame)
// (0 when they intersect): the least over vertex-face and edge-edge pairs.
double box_triangle_distance(const Eigen::Vector3d& h, const std::array<Eigen::Vector3d, 3>& t) {
  // Intersecting (no separating axis among the 13 of box and triangle): 0.
  const std::array<Eigen::Vector3d, 3> e = {t[1] - t[0], t[2] - t[1], t[0] - t[2]};
  std::vector<Eigen::Vector3d> axes = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), e[0].cross(e[1])};
  for (int i = 0; i < 3; ++i)
    for (const auto& edge : e) axes.push_back(Eigen::Vector3d::Unit(i).cross(edge));
  bool separated = false;
  for (const auto& a : axes) {
    const double p0 = a.dot(t[0]), p1 = a.dot(t[1]), p2 = a.dot(t[2]), r = h.dot(a.cwiseAbs());
    separated = separated || std::min({p0, p1, p2}) > r || std::max({p0, p1, p2}) < -r;
  }
  if (!separated) return 0;
  double best = 1e9;
  std::array<Eigen::Vector3d, 8> c;
  for (int i = 0; i < 8; ++i) c[size_t(i)] = Eigen::Vector3d(i & 1 ? h.x() : -h.x(), i & 2 ? h.y() : -h.y(), i & 4 ? h.z() : -h.z());
  for (const auto& v : c) best = std::min(best, point_triangle_distance(v, t[0], t[1], t[2]));
  for (const auto& v : t) best = std::min(best, (v.cwiseAbs() - h).cwiseMax(0.0).norm());
  for (int i = 0; i < 8; ++i)
    for (int bit : {1, 2, 4})
      if (!(i & bit))
        for (int k = 0; k < 3; ++k) best = std::min(best, segment_distance(c[size_t(i)], c[size_t(i | bit)], t[size_t(k)], t[size_t((k + 1) % 3)]));
  return best;
}

// Method: boxes and convex hulls are decided by the scene's own GJK on their vertices (Bullet's
// GJK overestimated such distances by up to 0.4 mm). Against an exact reference (box-triangle
// distance over every vertex-face and edge-edge pair, every triangle near the box) over a bumpy
// floor of small triangles, as an arm's link over a scanned floor, with and without a body
// margin: a box's distance and a hull of its corners' (rounded by Bullet's 0.1 mm margin, so up
// to ~0.09 mm larger) match it, and both report collisions where the box penetrates.
TEST(CollisionScene, BoxAndHullDistancesAreExactOverAFloor) {
  auto floor = std::make_shared<TriangleMesh>();
  const int n = 120;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const float x = -0.3f + 0.6f * float(i) / n, y = -0.3f + 0.6f * float(j) / n;
      floor->vertices.emplace_back(x, y, 0.01f * std::sin(17 * x) * std::cos(11 * y));
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      floor->faces.emplace_back(a, a + 1, a + n + 2);
      floor->faces.emplace_back(a, a + n + 2, a + n + 1);
    }
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(-1, 1);
  const Eigen::Vector3d size(0.3, 0.06, 0.05);
  std::vector<Eigen::Vector3f> corners;
  for (int i = 0; i < 8; ++i)
    corners.emplace_back(float((i & 1 ? 0.5 : -0.5) * size.x()), float((i & 2 ? 0.5 : -0.5) * size.y()), float((i & 4 ? 0.5 : -0.5) * size.z()));
  for (double margin : {0.0, 0.004}) {
    CollisionScene scene;
    scene.set_body(1, floor, Transform::Identity(), margin);
    int collisions = 0, clear = 0;
    for (int k = 0; k < 200; ++k) {
      const Transform T = Transform(Eigen::Translation3d(0.12 * u(rng), 0.12 * u(rng), 0.045 + 0.035 * u(rng))) *
                          Eigen::AngleAxisd(M_PI * u(rng), Eigen::Vector3d(0.3 * u(rng), 0.3 * u(rng), 1).normalized()) *
                          Eigen::AngleAxisd(0.4 * u(rng), Eigen::Vector3d::UnitX());
      const QueryShape box = box_at(T, size, "link");
      QueryShape hull = box;
      hull.kind = QueryShape::Kind::convex_hull;
      hull.points = corners;
      // The reference: nearest triangles first, each skipped when its bounding sphere is beyond
      // the best so far.
      const Transform T_box_world = T.inverse();
      std::vector<std::pair<double, size_t>> near;
      for (size_t f = 0; f < floor->faces.size(); ++f) {
        const Eigen::Vector3d c = T_box_world * floor->vertices[size_t(floor->faces[f][0])].cast<double>();
        near.emplace_back((c.cwiseAbs() - size / 2).cwiseMax(0.0).norm() - 0.01, f);
      }
      std::sort(near.begin(), near.end());
      double exact = 1e9;
      bool deep = false;  // a triangle meets the box shrunk by 0.3 mm
      for (const auto& [bound, f] : near) {
        if (bound > std::max(exact, 0.0)) break;
        std::array<Eigen::Vector3d, 3> t;
        for (int v = 0; v < 3; ++v) t[size_t(v)] = T_box_world * floor->vertices[size_t(floor->faces[f][v])].cast<double>();
        exact = std::min(exact, box_triangle_distance(size / 2, t));
        deep = deep || (exact == 0 && box_triangle_distance(size / 2 - Eigen::Vector3d::Constant(3e-4), t) == 0);
      }
      const bool penetrating = deep || exact - margin < -3e-4;
      exact -= margin;
      const auto d_box = scene.distance({box}, 0.1), d_hull = scene.distance({hull}, 0.1);
      if (exact < 3e-4) {  // touching or penetrating: the reference is not exact there
        if (penetrating) {
          ++collisions;
          EXPECT_TRUE(scene.check({box}).in_collision) << k;
          EXPECT_TRUE(scene.check({hull}).in_collision) << k;
          EXPECT_LT(d_box.distance_m, 0) << k;
          EXPECT_LT(d_hull.distance_m, 0) << k;
        }
        continue;
      }
      EXPECT_FALSE(scene.check({box}).in_collision) << k << " margin " << margin << " distance " << exact;
      EXPECT_FALSE(scene.check({hull}).in_collision) << k << " margin " << margin << " distance " << exact;
      ++clear;
      EXPECT_NEAR(d_box.distance_m, std::min(exact, 0.1), 1e-5) << k << " margin " << margin;
      EXPECT_NEAR(d_hull.distance_m, std::min(exact, 0.1), 1.5e-4) << k << " margin " << margin;
      if (!d_hull.closest) continue;
      // Witnesses: as far apart as the distance (plus the margin); the body's on the floor.
      const auto& w = *d_hull.closest;
      EXPECT_NEAR((w.point_on_shape - w.point_on_body).norm(), d_hull.distance_m + margin, 2e-5) << k;
      const auto ray = scene.raycast(w.point_on_body + Eigen::Vector3d(0, 0, 0.05), {0, 0, -1}, 0.1);
      ASSERT_TRUE(ray.hit) << k;
      EXPECT_NEAR(ray.point.z(), w.point_on_body.z(), 1e-5) << k;
    }
    // Some clear, some penetrating beyond the touching band: the comparison can fail both ways.
    EXPECT_GE(clear, 60) << "margin " << margin;
    EXPECT_GE(collisions, 20) << "margin " << margin;
  }
}

TEST(CollisionScene, PrebuiltGeometryIsSharedAndMovable) {
  auto mesh = box_mesh({0.2f, 0.2f, 0.2f});
  const auto geometry = CollisionScene::build_geometry(mesh);
  CollisionScene scene;
  scene.set_body(1, geometry, Transform(Eigen::Translation3d(1, 0, 0)));
  scene.set_body(2, geometry, Transform(Eigen::Translation3d(-1, 0, 0)));
  EXPECT_EQ(scene.triangle_count(), 24u);
  EXPECT_TRUE(scene.check({sphere_at({1.1, 0, 0}, 0.01)}).in_collision);
  EXPECT_TRUE(scene.check({sphere_at({-1.1, 0, 0}, 0.01)}).in_collision);
  const auto hit = scene.raycast({0, 0, 0}, {1, 0, 0}, 5);
  ASSERT_TRUE(hit.hit);
  EXPECT_EQ(hit.body, 1);
  EXPECT_NEAR(hit.distance_m, 0.9, 1e-6);
  EXPECT_NEAR(hit.normal.x(), -1.0, 1e-6);  // facing the ray's origin
  EXPECT_THROW(CollisionScene::build_geometry(std::make_shared<TriangleMesh>()), Error);
}

}  // namespace
}  // namespace artisan::worldmodel
