#pragma once
// Simulated Minolta Vivid 700: laser light-stripe triangulation. A 200 x 200 range image with a
// 400 x 400 colour image as texture, 0.6 to 2.5 m standoff. Errors modelled: range noise along
// the line of sight growing with the square of the range (triangulation), shadowing where the
// laser or the camera cannot see a point (emitter-camera baseline), dropouts on grazing surfaces.
// Sources of the figures: see sim/README.md.
#include <cstdint>
#include <map>
#include <string>

#include "artisan/sim/acquisition.hpp"
#include "artisan/sim/renderer.hpp"

namespace artisan::sim {

struct VividParams {
  int range_width = 200;              ///< range image width [pixels] (Vivid 700 spec)
  int range_height = 200;             ///< range image height [pixels] (Vivid 700 spec)
  int color_width = 400;              ///< colour image width [pixels] (Vivid 700 spec)
  int color_height = 400;             ///< colour image height [pixels] (Vivid 700 spec)
  double horizontal_fov_rad = 0.5;    ///< field of view [rad] (~29 deg; assumed, mid zoom)
  double min_fov_rad = 0.2;           ///< zoom lens, narrowest field of view [rad] (~11 deg; assumed)
  double max_fov_rad = 0.75;          ///< zoom lens, widest field of view [rad] (~43 deg; assumed)
  double min_range_m = 0.6;           ///< nearest measurable point [m] (Vivid 700 spec)
  double max_range_m = 2.5;           ///< farthest measurable point [m] (Vivid 700 spec)
  double baseline_m = 0.15;           ///< laser emitter above the camera, along -y of the sensor [m] (assumed)
  double noise_sigma_at_1m_m = 0.0008;  ///< range noise sigma at 1 m; sigma(z) = this * (z / 1 m)^2 [m] (assumed)
  double grazing_start_rad = 1.05;    ///< incidence beyond which points start to drop out [rad] (60 deg)
  double grazing_limit_rad = 1.40;    ///< incidence beyond which every point drops out [rad] (80 deg)
  double random_dropout = 0.002;      ///< probability of a dropout anywhere [-]
  double shadow_tolerance_m = 0.003;  ///< shadow-map comparison tolerance [m] (plus 0.2 % of range)
  double scan_time_s = 0.6;           ///< acquisition time [s] (Vivid 700 spec)
};

/// Defaults overridden by name (SensorSpec::params); throws artisan::Error for an unknown name.
VividParams vivid_params(const std::map<std::string, double>& overrides);
/// The model's range-noise standard deviation at depth z [m].
double vivid_range_sigma(const VividParams& params, double z_m);

/// One Vivid acquisition of the workcell from T_world_sensor (sensor frame = the receiving
/// camera: x right, y down, z forward). Deterministic for a given seed.
Acquisition scan_vivid(Renderer& renderer, const Workcell& cell, const Transform& T_world_sensor,
                       const VividParams& params, uint64_t seed);

}  // namespace artisan::sim
