#pragma once
// Synthetic range images of analytic surfaces: a pinhole camera (sensor frame = camera frame,
// x right, y down, z forward) casts one ray per pixel and keeps the nearest hit among planes and
// spheres. Shared by the meshing tests and bench_meshing.
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "artisan/core/camera.hpp"
#include "artisan/core/range_image.hpp"

namespace artisan::test {

struct AnalyticPlane {
  Eigen::Vector3d normal;  ///< unit
  double offset = 0;       ///< points p with normal.p = offset
  /// Optional: only the part of the plane where this returns true (e.g. one side of a step).
  std::function<bool(const Eigen::Vector3d&)> keep;
};

struct AnalyticSphere {
  Eigen::Vector3d centre;
  double radius = 0;
};

struct AnalyticScene {
  std::vector<AnalyticPlane> planes;
  std::vector<AnalyticSphere> spheres;
};

inline PinholeCamera vga_camera() { return PinholeCamera{640, 480, 525.0, 525.0, 319.5, 239.5}; }

/// Renders the scene; pixels whose ray hits nothing, or for which hole(x, y) is true, are invalid.
inline RangeImage render_range_image(const PinholeCamera& camera, const AnalyticScene& scene,
                                     const std::function<bool(int, int)>& hole = nullptr) {
  RangeImage image = RangeImage::empty_of_size(camera.width, camera.height);
  image.sensor.kind = "synthetic-pinhole";
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      if (hole && hole(x, y)) continue;
      const Eigen::Vector3d ray = camera.unproject(Eigen::Vector2d(x, y), 1.0).normalized();
      double best = std::numeric_limits<double>::infinity();
      for (const auto& plane : scene.planes) {
        const double denom = plane.normal.dot(ray);
        if (std::abs(denom) < 1e-12) continue;
        const double t = plane.offset / denom;
        if (t > 0 && t < best && (!plane.keep || plane.keep(t * ray))) best = t;
      }
      for (const auto& sphere : scene.spheres) {
        const double b = ray.dot(sphere.centre);
        const double disc = b * b - sphere.centre.squaredNorm() + sphere.radius * sphere.radius;
        if (disc < 0) continue;
        const double t = b - std::sqrt(disc);
        if (t > 0 && t < best) best = t;
      }
      if (!std::isfinite(best)) continue;
      const size_t i = image.index(x, y);
      image.points_sensor[i] = (best * ray).cast<float>();
      image.valid[i] = 1;
    }
  }
  return image;
}

}  // namespace artisan::test
