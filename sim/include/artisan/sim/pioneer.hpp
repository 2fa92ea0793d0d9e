#pragma once
// Simulated Pioneer trinocular stereo head: three cameras in an L (reference "left", "right"
// beside it along +x, "top" above it along -y) render textured images; range comes from running
// semi-global block matching (OpenCV SGBM) on the horizontal and the vertical pair and fusing the
// two disparity maps, so its errors are real stereo errors. The head sits on a pan/tilt unit.
#include <cstdint>
#include <map>
#include <string>

#include "artisan/sim/acquisition.hpp"
#include "artisan/sim/renderer.hpp"

namespace artisan::sim {

struct PioneerParams {
  int width = 640;                    ///< camera image width [pixels]
  int height = 480;                   ///< camera image height [pixels]
  double horizontal_fov_rad = 1.0;    ///< camera field of view [rad] (~57 deg)
  double baseline_m = 0.2;            ///< left-right and left-top distance [m]
  int num_disparities = 128;          ///< SGBM disparity search range [pixels], multiple of 16
  int block_size = 7;                 ///< SGBM matching block [pixels], odd
  int uniqueness_ratio = 10;          ///< SGBM uniqueness margin [%]
  int speckle_window = 100;           ///< SGBM speckle filter window [pixels]
  int speckle_range = 2;              ///< SGBM speckle filter disparity range [pixels]
  double fuse_tolerance_px = 1.0;     ///< both pairs valid and further apart than this: no data [pixels]
  double image_noise_sigma = 2.0;     ///< camera noise added to each grey level [0..255 units]
  double min_range_m = 0.5;           ///< points nearer than this are dropped [m]
  double max_range_m = 8.0;           ///< points farther than this are dropped [m]
  double settle_time_s = 0.1;         ///< after a pan/tilt move, before the exposure [s]
};

PioneerParams pioneer_params(const std::map<std::string, double>& overrides);

/// One Pioneer acquisition from the reference (left) camera at T_world_sensor.
/// Deterministic for a given seed. Its ground truth counts as visible only what the head can
/// measure: a left-camera pixel in range whose point the right or the top camera sees too.
Acquisition scan_pioneer(Renderer& renderer, const Workcell& cell, const Transform& T_world_sensor,
                         const PioneerParams& params, uint64_t seed);

}  // namespace artisan::sim
