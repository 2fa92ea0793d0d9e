#include "artisan/sim/pioneer.hpp"

#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "artisan/core/error.hpp"
#include "params_util.hpp"
#include "random.hpp"

namespace artisan::sim {

PioneerParams pioneer_params(const std::map<std::string, double>& overrides) {
  PioneerParams p;
  apply_overrides("pioneer-trinocular", overrides,
                  {{"width", &p.width}, {"height", &p.height}, {"horizontal_fov_rad", &p.horizontal_fov_rad},
                   {"baseline_m", &p.baseline_m}, {"num_disparities", &p.num_disparities}, {"block_size", &p.block_size},
                   {"uniqueness_ratio", &p.uniqueness_ratio}, {"speckle_window", &p.speckle_window},
                   {"speckle_range", &p.speckle_range}, {"fuse_tolerance_px", &p.fuse_tolerance_px},
                   {"image_noise_sigma", &p.image_noise_sigma}, {"min_range_m", &p.min_range_m},
                   {"max_range_m", &p.max_range_m}, {"settle_time_s", &p.settle_time_s}});
  if (p.width <= 0 || p.height <= 0) throw Error("pioneer-trinocular: image size must be positive");
  if (p.num_disparities <= 0 || p.num_disparities % 16 != 0)
    throw Error("pioneer-trinocular: num_disparities must be a positive multiple of 16, got " + std::to_string(p.num_disparities));
  if (p.block_size < 1 || p.block_size % 2 == 0) throw Error("pioneer-trinocular: block_size must be odd, got " + std::to_string(p.block_size));
  if (!(p.baseline_m > 0)) throw Error("pioneer-trinocular: baseline_m must be positive");
  return p;
}

namespace {

cv::Mat grey_with_noise(const ColorImage& img, double sigma, Rng& rng) {
  cv::Mat rgb(img.height, img.width, CV_8UC3, const_cast<uint8_t*>(img.pixels.data()));
  cv::Mat grey;
  cv::cvtColor(rgb, grey, cv::COLOR_RGB2GRAY);
  if (sigma > 0)
    for (int y = 0; y < grey.rows; ++y) {
      auto* row = grey.ptr<uint8_t>(y);
      for (int x = 0; x < grey.cols; ++x) row[x] = cv::saturate_cast<uint8_t>(row[x] + sigma * rng.normal());
    }
  return grey;
}

// Disparity [pixels] of `ref` against `other`, where a point at depth z appears f b / z pixels
// further left in `other`; NaN where SGBM finds no match.
cv::Mat disparity(const cv::Mat& ref, const cv::Mat& other, const PioneerParams& p) {
  const int cn = 1;
  auto sgbm = cv::StereoSGBM::create(0, p.num_disparities, p.block_size, 8 * cn * p.block_size * p.block_size,
                                     32 * cn * p.block_size * p.block_size, 1, 0, p.uniqueness_ratio, p.speckle_window,
                                     p.speckle_range, cv::StereoSGBM::MODE_SGBM_3WAY);
  cv::Mat d16;
  sgbm->compute(ref, other, d16);
  cv::Mat d(d16.size(), CV_32F);
  for (int y = 0; y < d16.rows; ++y)
    for (int x = 0; x < d16.cols; ++x) {
      const int16_t v = d16.at<int16_t>(y, x);
      d.at<float>(y, x) = v > 0 ? v / 16.0f : NAN;
    }
  return d;
}

}  // namespace

Acquisition scan_pioneer(Renderer& renderer, const Workcell& cell, const Transform& T_world_sensor, const PioneerParams& p,
                         uint64_t seed) {
  const PinholeCamera cam = camera_from_fov(p.width, p.height, p.horizontal_fov_rad);
  const double near_m = 0.5 * p.min_range_m, far_m = 2.0 * p.max_range_m;
  Transform T_sensor_right = Transform::Identity(), T_sensor_top = Transform::Identity();
  T_sensor_right.translation() = Eigen::Vector3d(p.baseline_m, 0, 0);
  T_sensor_top.translation() = Eigen::Vector3d(0, -p.baseline_m, 0);

  RenderOptions colour_and_truth;
  colour_and_truth.near_m = near_m;
  colour_and_truth.far_m = far_m;
  const RenderResult left = renderer.render(cell, cam, T_world_sensor, colour_and_truth);
  RenderOptions colour_and_depth = colour_and_truth;
  colour_and_depth.instances = false;
  const RenderResult right = renderer.render(cell, cam, T_world_sensor * T_sensor_right, colour_and_depth);
  const RenderResult top = renderer.render(cell, cam, T_world_sensor * T_sensor_top, colour_and_depth);

  Rng rng(seed);
  const cv::Mat gl = grey_with_noise(left.color, p.image_noise_sigma, rng);
  const cv::Mat gr = grey_with_noise(right.color, p.image_noise_sigma, rng);
  const cv::Mat gt = grey_with_noise(top.color, p.image_noise_sigma, rng);
  const cv::Mat d_h = disparity(gl, gr, p);
  // Vertical pair: transpose and mirror so "top" plays the right camera: a point appears
  // f b / z pixels lower in "top", which becomes f b / z further left after the mirror.
  cv::Mat glt, gtt;
  cv::transpose(gl, glt);
  cv::flip(glt, glt, 1);
  cv::transpose(gt, gtt);
  cv::flip(gtt, gtt, 1);
  const cv::Mat d_v_rot = disparity(glt, gtt, p);

  const int W = p.width, H = p.height;
  Acquisition acq;
  RangeImage& r = acq.range;
  r = RangeImage::empty_of_size(W, H);
  const double fb = cam.fx * p.baseline_m;
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const size_t i = static_cast<size_t>(v) * W + u;
      const float dh = d_h.at<float>(v, u);
      const float dv = d_v_rot.at<float>(u, H - 1 - v);
      float d = NAN;
      if (!std::isnan(dh) && !std::isnan(dv)) d = std::abs(dh - dv) <= p.fuse_tolerance_px ? 0.5f * (dh + dv) : NAN;
      else if (!std::isnan(dh)) d = dh;
      else if (!std::isnan(dv)) d = dv;
      if (std::isnan(d) || d <= 0) continue;
      const double z = fb / d;
      if (z < p.min_range_m || z > p.max_range_m) continue;
      r.points_sensor[i] = cam.unproject({u, v}, z).cast<float>();
      r.valid[i] = 1;
    }
  r.sensor.kind = "pioneer-trinocular";
  r.sensor.T_world_sensor = T_world_sensor;
  r.sensor.attributes["seed"] = std::to_string(seed);
  r.sensor.attributes["simulated"] = "artisan-sim";
  auto add_image = [&](const char* name, const ColorImage& img, const Transform& T) {
    CameraImage c;
    c.name = name;
    c.image = img;
    c.camera = cam;
    c.T_sensor_camera = T;
    r.images.push_back(std::move(c));
  };
  add_image("left", left.color, Transform::Identity());
  add_image("right", right.color, T_sensor_right);
  add_image("top", top.color, T_sensor_top);

  // What the head can measure at all: a left pixel in range whose point the right or the top
  // camera sees too (a stereo pair measures only what both its cameras see; the head fuses the
  // two pairs and keeps either alone). A surface only the left camera sees - in a slot, behind
  // an edge from the others - is not visible, however plainly the left image shows it.
  const Transform T_right_sensor = T_sensor_right.inverse(), T_top_sensor = T_sensor_top.inverse();
  constexpr double kTolerance = 0.003;  // [m] as the Vivid's shadow test, plus 0.2% of the depth
  std::vector<char> measurable(static_cast<size_t>(W) * H, 0);
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const size_t i = static_cast<size_t>(v) * W + u;
      const float z = left.depth_m[i];
      if (z <= 0 || z < p.min_range_m || z > p.max_range_m) continue;
      const Eigen::Vector3d p_sensor = cam.unproject({u, v}, z);
      measurable[i] = sees_point(right, cam, T_right_sensor * p_sensor, kTolerance) || sees_point(top, cam, T_top_sensor * p_sensor, kTolerance);
    }
  acq.truth = view_truth(renderer, cell, r.sensor.kind, seed, cam, T_world_sensor, left.instance_ids, left.depth_m, near_m, far_m, measurable);
  return acq;
}

}  // namespace artisan::sim
