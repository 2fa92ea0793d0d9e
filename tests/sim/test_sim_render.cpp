// OSMesa rendering and exact unprojection, checked against analytic scenes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "artisan/sim/renderer.hpp"
#include "artisan/sim/shapes.hpp"
#include "artisan/sim/workcell.hpp"

namespace artisan::sim {
namespace {

Body make_body(const std::string& name, TriangleMesh mesh, const Transform& T_world_body) {
  Body b;
  b.name = name;
  b.mesh = std::move(mesh);
  b.T_world_body = T_world_body;
  return b;
}

Workcell cell_of(std::vector<Body> bodies) {
  Workcell c;
  c.bodies = std::move(bodies);
  for (size_t i = 0; i < c.bodies.size(); ++i) c.bodies[i].instance_id = static_cast<int>(i) + 1;
  return c;
}

Transform translation(double x, double y, double z) { return Transform(Eigen::Translation3d(x, y, z)); }

// Method: a wall (the face of a thick box) facing the camera at z = 1.7 m fills the view; every
// pixel's depth must be 1.7 m and unproject onto the plane z = 1.7, to depth-buffer precision.
TEST(SimRender, FrontoParallelPlaneDepthIsExact) {
  const double d = 1.7;
  auto cell = cell_of({make_body("wall", make_box({10, 10, 0.2}), translation(0, 0, d + 0.1))});
  Renderer renderer(cell);
  const PinholeCamera cam = camera_from_fov(160, 120, 1.0);
  RenderOptions opt;
  opt.near_m = 0.3;
  opt.far_m = 5.0;
  const auto r = renderer.render(cell, cam, Transform::Identity(), opt);
  double worst = 0;
  for (size_t i = 0; i < r.depth_m.size(); ++i) {
    ASSERT_GT(r.depth_m[i], 0.f) << "pixel " << i;
    worst = std::max(worst, std::abs(r.depth_m[i] - d));
    EXPECT_EQ(r.instance_ids[i], 1);
  }
  std::printf("fronto-parallel plane: worst depth error %.3g m\n", worst);
  EXPECT_LT(worst, 2e-5) << "worst depth error " << worst;
  ASSERT_EQ(r.color.width, 160);
}

// Method: a plane tilted by 50 degrees about the camera's y axis (depth changes ~1.2 mm per
// pixel across the image). Unprojected pixel centres must lie on the analytic plane; a
// half-pixel error in the pixel convention would put them about 0.6 mm off.
TEST(SimRender, TiltedPlaneUnprojectsOntoThePlane) {
  Transform T_world_plane = Transform::Identity();
  T_world_plane.linear() = Eigen::AngleAxisd(50.0 * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T_world_plane.translation() = Eigen::Vector3d(0.05, -0.02, 1.3);
  // The box's +z face is the plane; shift the box back by half its thickness along its normal.
  const Eigen::Vector3d normal = T_world_plane.linear().col(2);
  Transform T_world_box = T_world_plane;
  T_world_box.translation() += 0.1 * normal;
  auto cell = cell_of({make_body("plane", make_box({10, 10, 0.2}), T_world_box)});
  // The face at +z of the box is 0.1 in front of the box centre along +normal: move the box so
  // that its -z face (the one towards the camera) is the plane.
  Renderer renderer(cell);
  const PinholeCamera cam = camera_from_fov(200, 150, 0.9);
  RenderOptions opt;
  opt.near_m = 0.3;
  opt.far_m = 6.0;
  const auto r = renderer.render(cell, cam, Transform::Identity(), opt);
  const auto pts = unproject_depth(cam, r.depth_m);
  double worst = 0;
  int n = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    if (r.depth_m[i] <= 0) continue;
    ++n;
    worst = std::max(worst, std::abs((pts[i].cast<double>() - T_world_plane.translation()).dot(normal)));
  }
  EXPECT_GT(n, 200 * 150 * 9 / 10);
  std::printf("tilted plane: worst distance %.3g m\n", worst);
  EXPECT_LT(worst, 5e-5) << "worst distance to the plane " << worst;
}

// Method: a finely tessellated sphere (radius 0.25 m, 512 facets around: chords lie at most
// r(1 - cos(pi/512)) = 5 µm inside) at 1.5 m. Every hit unprojects to within that band of
// the sphere; pixels whose ray analytically hits the sphere at least one pixel inside the
// silhouette carry its instance id, pixels whose ray misses it by a pixel do not.
TEST(SimRender, SphereUnprojectsOntoTheSphereAndSilhouetteIsExact) {
  const Eigen::Vector3d c(0.1, 0.05, 1.5);
  const double radius = 0.25;
  auto cell = cell_of({make_body("sphere", make_sphere(radius, 512), translation(c.x(), c.y(), c.z()))});
  Renderer renderer(cell);
  const PinholeCamera cam = camera_from_fov(240, 180, 0.6);
  RenderOptions opt;
  opt.near_m = 0.5;
  opt.far_m = 4.0;
  const auto r = renderer.render(cell, cam, Transform::Identity(), opt);
  const auto pts = unproject_depth(cam, r.depth_m);
  double worst = 0;
  int hits = 0, mismatches = 0;
  const double pixel_angle = 1.0 / cam.fx;
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      const size_t i = static_cast<size_t>(v) * cam.width + u;
      const Eigen::Vector3d ray = cam.unproject({u, v}, 1.0).normalized();
      const double miss_angle = std::asin(std::min(1.0, (c - c.dot(ray) * ray).norm() / c.norm())) -
                                std::asin(radius / c.norm());  // < 0 inside the silhouette
      if (r.depth_m[i] > 0) {
        ++hits;
        worst = std::max(worst, std::abs((pts[i].cast<double>() - c).norm() - radius));
      }
      if (miss_angle < -1.5 * pixel_angle && r.instance_ids[i] != 1) ++mismatches;
      if (miss_angle > 1.5 * pixel_angle && r.instance_ids[i] != 0) ++mismatches;
    }
  EXPECT_GT(hits, 1000);
  std::printf("sphere: worst distance %.3g m, silhouette mismatches %d\n", worst, mismatches);
  EXPECT_LT(worst, 2e-5) << "worst distance to the sphere " << worst;
  EXPECT_EQ(mismatches, 0);
}

// Method: two boxes, the nearer one hiding part of the farther; instance ids follow depth.
TEST(SimRender, InstanceIdsFollowOcclusionAndOnlyInstanceDrawsOne) {
  auto cell = cell_of({make_body("back", make_box({2, 2, 0.1}), translation(0, 0, 2.0)),
                       make_body("front", make_box({0.2, 0.2, 0.1}), translation(0, 0, 1.0))});
  Renderer renderer(cell);
  const PinholeCamera cam = camera_from_fov(100, 100, 0.8);
  const auto r = renderer.render(cell, cam, Transform::Identity());
  EXPECT_EQ(r.instance_ids[50 * 100 + 50], 2);
  EXPECT_NEAR(r.depth_m[50 * 100 + 50], 0.95, 1e-5);
  EXPECT_EQ(r.instance_ids[5 * 100 + 5], 1);
  RenderOptions alone;
  alone.only_instance = 1;
  const auto a = renderer.render(cell, cam, Transform::Identity(), alone);
  EXPECT_EQ(a.instance_ids[50 * 100 + 50], 1);
  EXPECT_NEAR(a.depth_m[50 * 100 + 50], 1.95, 1e-5);
}

}  // namespace
}  // namespace artisan::sim
