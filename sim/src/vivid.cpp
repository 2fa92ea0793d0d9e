#include "artisan/sim/vivid.hpp"

#include <algorithm>
#include <cmath>

#include "artisan/core/error.hpp"
#include "params_util.hpp"
#include "random.hpp"

namespace artisan::sim {

VividParams vivid_params(const std::map<std::string, double>& overrides) {
  VividParams p;
  apply_overrides("minolta-vivid-700", overrides,
                  {{"range_width", &p.range_width}, {"range_height", &p.range_height}, {"color_width", &p.color_width},
                   {"color_height", &p.color_height}, {"horizontal_fov_rad", &p.horizontal_fov_rad},
                   {"min_fov_rad", &p.min_fov_rad}, {"max_fov_rad", &p.max_fov_rad},
                   {"min_range_m", &p.min_range_m}, {"max_range_m", &p.max_range_m}, {"baseline_m", &p.baseline_m},
                   {"noise_sigma_at_1m_m", &p.noise_sigma_at_1m_m}, {"grazing_start_rad", &p.grazing_start_rad},
                   {"grazing_limit_rad", &p.grazing_limit_rad}, {"random_dropout", &p.random_dropout},
                   {"shadow_tolerance_m", &p.shadow_tolerance_m}, {"scan_time_s", &p.scan_time_s}});
  if (p.range_width <= 0 || p.range_height <= 0 || p.color_width <= 0 || p.color_height <= 0)
    throw Error("minolta-vivid-700: image sizes must be positive");
  if (!(p.min_range_m > 0 && p.max_range_m > p.min_range_m)) throw Error("minolta-vivid-700: need 0 < min_range_m < max_range_m");
  if (!(p.grazing_limit_rad > p.grazing_start_rad)) throw Error("minolta-vivid-700: need grazing_start_rad < grazing_limit_rad");
  if (!(p.min_fov_rad > 0 && p.min_fov_rad <= p.horizontal_fov_rad && p.horizontal_fov_rad <= p.max_fov_rad && p.max_fov_rad < 3.0))
    throw Error("minolta-vivid-700: need 0 < min_fov_rad <= horizontal_fov_rad <= max_fov_rad < 3 rad (the zoom range), got " +
                std::to_string(p.min_fov_rad) + ", " + std::to_string(p.horizontal_fov_rad) + ", " + std::to_string(p.max_fov_rad));
  return p;
}

double vivid_range_sigma(const VividParams& p, double z_m) { return p.noise_sigma_at_1m_m * z_m * z_m; }

namespace {

// Unit surface normal at pixel i from its neighbours (central differences where the neighbours
// lie on the same surface, else one-sided); zero when it cannot be estimated.
Eigen::Vector3f pixel_normal(const std::vector<Eigen::Vector3f>& pts, const std::vector<float>& z, int W, int H, int u, int v) {
  const size_t i = static_cast<size_t>(v) * W + u;
  auto ok = [&](int uu, int vv) {
    if (uu < 0 || vv < 0 || uu >= W || vv >= H) return false;
    const float zz = z[static_cast<size_t>(vv) * W + uu];
    return zz > 0 && std::abs(zz - z[i]) < 0.05f * z[i];
  };
  auto P = [&](int uu, int vv) { return pts[static_cast<size_t>(vv) * W + uu]; };
  Eigen::Vector3f dx, dy;
  if (ok(u + 1, v) && ok(u - 1, v)) dx = P(u + 1, v) - P(u - 1, v);
  else if (ok(u + 1, v)) dx = P(u + 1, v) - P(u, v);
  else if (ok(u - 1, v)) dx = P(u, v) - P(u - 1, v);
  else return Eigen::Vector3f::Zero();
  if (ok(u, v + 1) && ok(u, v - 1)) dy = P(u, v + 1) - P(u, v - 1);
  else if (ok(u, v + 1)) dy = P(u, v + 1) - P(u, v);
  else if (ok(u, v - 1)) dy = P(u, v) - P(u, v - 1);
  else return Eigen::Vector3f::Zero();
  const Eigen::Vector3f n = dx.cross(dy);
  const float len = n.norm();
  return len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f::Zero();
}

}  // namespace

Acquisition scan_vivid(Renderer& renderer, const Workcell& cell, const Transform& T_world_sensor, const VividParams& p,
                       uint64_t seed) {
  const PinholeCamera range_cam = camera_from_fov(p.range_width, p.range_height, p.horizontal_fov_rad);
  const PinholeCamera color_cam = camera_from_fov(p.color_width, p.color_height, p.horizontal_fov_rad);
  const double near_m = 0.5 * p.min_range_m, far_m = 1.5 * p.max_range_m;

  RenderOptions geometry;
  geometry.color = false;
  geometry.near_m = near_m;
  geometry.far_m = far_m;
  const RenderResult truth = renderer.render(cell, range_cam, T_world_sensor, geometry);
  RenderOptions colour;
  colour.depth = false;
  colour.instances = false;
  colour.near_m = near_m;
  colour.far_m = far_m;
  const RenderResult color = renderer.render(cell, color_cam, T_world_sensor, colour);

  // The laser's view: a pinhole at the emitter (baseline_m along -y), parallel to the camera,
  // twice the range image's angular resolution, wide enough to cover the camera's frustum over
  // the measurable depths.
  const Eigen::Vector3d emitter_sensor(0, -p.baseline_m, 0);
  PinholeCamera laser_cam;
  {
    double max_x = 0, max_y = 0;
    for (double z : {p.min_range_m, p.max_range_m})
      for (double u : {-0.5, range_cam.width - 0.5})
        for (double v : {-0.5, range_cam.height - 0.5}) {
          const Eigen::Vector3d q = range_cam.unproject({u, v}, z) - emitter_sensor;
          max_x = std::max(max_x, std::abs(q.x() / q.z()));
          max_y = std::max(max_y, std::abs(q.y() / q.z()));
        }
    laser_cam.fx = laser_cam.fy = 2 * range_cam.fx;
    laser_cam.width = 2 * static_cast<int>(std::ceil(laser_cam.fx * max_x)) + 2;
    laser_cam.height = 2 * static_cast<int>(std::ceil(laser_cam.fy * max_y)) + 2;
    laser_cam.cx = (laser_cam.width - 1) / 2.0;
    laser_cam.cy = (laser_cam.height - 1) / 2.0;
  }
  Transform T_sensor_laser = Transform::Identity();
  T_sensor_laser.translation() = emitter_sensor;
  RenderOptions shadow_opts;
  shadow_opts.color = false;
  shadow_opts.instances = false;
  shadow_opts.near_m = near_m * 0.5;
  shadow_opts.far_m = far_m;
  const RenderResult laser = renderer.render(cell, laser_cam, T_world_sensor * T_sensor_laser, shadow_opts);

  const int W = range_cam.width, H = range_cam.height;
  const auto points_true = unproject_depth(range_cam, truth.depth_m);
  Acquisition acq;
  RangeImage& r = acq.range;
  r = RangeImage::empty_of_size(W, H);
  Rng rng(seed);
  std::vector<char> measurable(static_cast<size_t>(W) * H, 0);  // in range and lit: what the scanner can measure
  for (int v = 0; v < H; ++v) {
    for (int u = 0; u < W; ++u) {
      const size_t i = static_cast<size_t>(v) * W + u;
      // Draw the same number of random numbers for every pixel, so one pixel's fate does not
      // shift the noise of the others.
      const double n_noise = rng.normal();
      const double n_drop = rng.uniform();
      const double n_graze = rng.uniform();
      r.uv[i] = color_cam.project(range_cam.unproject({u, v}, 1.0)).value().cast<float>();
      const float z = truth.depth_m[i];
      if (z <= 0 || z < p.min_range_m || z > p.max_range_m) continue;
      const Eigen::Vector3f& ps = points_true[i];
      // Shadowing: the laser must reach the point (the camera sees it by construction).
      const Eigen::Vector3d pl = ps.cast<double>() - emitter_sensor;
      if (!sees_point(laser, laser_cam, pl, p.shadow_tolerance_m)) continue;
      // Grazing incidence, for the camera or the laser, whichever is worse. Beyond the limit the
      // scanner never returns anything: not measurable, like a shadow (a flange seen edge-on is
      // hidden from it however plainly the camera sees its face).
      const Eigen::Vector3f n = pixel_normal(points_true, truth.depth_m, W, H, u, v);
      double p_drop = 0;
      if (n.squaredNorm() > 0) {
        const double cos_cam = std::abs(n.dot(ps.normalized()));
        const double cos_laser = std::abs(n.cast<double>().dot(pl.normalized()));
        const double incidence = std::acos(std::min(1.0, std::min(cos_cam, cos_laser)));
        if (incidence >= p.grazing_limit_rad) continue;
        p_drop = std::clamp((incidence - p.grazing_start_rad) / (p.grazing_limit_rad - p.grazing_start_rad), 0.0, 1.0);
      }
      measurable[i] = 1;  // what is lost from here on is noise (grazing dropouts, random dropouts), not hidden
      if (n_graze < p_drop) continue;
      if (n_drop < p.random_dropout) continue;
      // Range noise along the line of sight.
      const double z_noisy = z + vivid_range_sigma(p, z) * n_noise;
      r.points_sensor[i] = range_cam.unproject({u, v}, z_noisy).cast<float>();
      r.valid[i] = 1;
    }
  }
  r.sensor.kind = "minolta-vivid-700";
  r.sensor.T_world_sensor = T_world_sensor;
  r.sensor.attributes["seed"] = std::to_string(seed);
  r.sensor.attributes["simulated"] = "artisan-sim";
  CameraImage cam;
  cam.name = "color";
  cam.image = color.color;
  cam.camera = color_cam;
  r.images.push_back(std::move(cam));

  acq.truth = view_truth(renderer, cell, r.sensor.kind, seed, range_cam, T_world_sensor, truth.instance_ids, truth.depth_m, near_m, far_m, measurable);
  return acq;
}

}  // namespace artisan::sim
