#pragma once
// Environmental sensors aboard the rig: gamma dose rate from point sources (inverse square law,
// exponential attenuation by air and by the solid bodies on the way), temperature and humidity
// from the workcell's fields. Readings carry the time and the rig pose.
#include <cstdint>
#include <map>
#include <string>

#include "artisan/sim/acquisition.hpp"
#include "artisan/sim/workcell.hpp"

namespace artisan::sim {

struct EnvironmentSensorParams {
  double dose_relative_sigma = 0.05;   ///< dose-rate reading noise, relative [-]
  double temperature_sigma_C = 0.1;    ///< temperature reading noise [°C]
  double humidity_sigma_percent = 1.0; ///< humidity reading noise [% RH]
};

EnvironmentSensorParams environment_params(const std::map<std::string, double>& overrides);

/// Noise-free gamma dose rate at a point [µSv/h]: Σ D₁ (1 m / r)² exp(-μ_air r - μ_solid L),
/// L the path length through bodies between source and point.
double dose_rate_uSv_per_h(const Workcell& cell, const Eigen::Vector3d& p_world);
/// Path length [m] of the segment a-b inside the workcell's (closed) body meshes.
double path_length_in_bodies(const Workcell& cell, const Eigen::Vector3d& a_world, const Eigen::Vector3d& b_world);

/// A reading at the rig pose; noise from `seed`.
EnvironmentReading read_environment(const Workcell& cell, const Transform& T_world_rig, double time_s,
                                    const EnvironmentSensorParams& params, uint64_t seed);

}  // namespace artisan::sim
