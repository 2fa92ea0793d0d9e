#pragma once
// The simulated workcell as a whole: loads and settles a workcell, keeps the simulated clock
// and the pan/tilt state, and takes acquisitions with any of its sensors by name.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "artisan/sim/acquisition.hpp"
#include "artisan/sim/physics.hpp"
#include "artisan/sim/renderer.hpp"
#include "artisan/sim/workcell.hpp"

namespace artisan::sim {

struct ScanRequest {
  std::string sensor;                        ///< a sensor of the workcell, by name
  std::optional<Transform> T_world_sensor;   ///< overrides the sensor's mount
  std::optional<double> pan_rad;             ///< pan/tilt sensors: move there first [rad]
  std::optional<double> tilt_rad;            ///< [rad]
  /// Sensors with a zoom lens (the Vivid): the horizontal field of view for this scan [rad],
  /// within the model's zoom range (VividParams::min_fov_rad, max_fov_rad).
  std::optional<double> horizontal_fov_rad;
  uint64_t seed = 0;                         ///< noise seed
};

class Simulator {
 public:
  /// Takes the workcell, settles its dropped objects (physics) and makes the renderer.
  explicit Simulator(Workcell cell, const SettleParams& settle_params = {});
  ~Simulator();

  const Workcell& workcell() const { return cell_; }
  const SettleResult& settle_result() const { return settle_; }
  double clock_s() const { return clock_s_; }

  /// An acquisition with the named sensor. Range sensors also carry an environment reading
  /// when the workcell has an "environment" sensor. Throws artisan::Error for an unknown
  /// sensor, a pan/tilt beyond the unit's limits, or pan/tilt asked of a sensor without one.
  Acquisition scan(const ScanRequest& request);
  /// An environment reading with the named environment sensor (at its mount or `T_world_rig`).
  EnvironmentReading read_environment(const std::string& sensor, const std::optional<Transform>& T_world_rig, uint64_t seed);
  /// A picture of the cell.
  RenderResult render(const PinholeCamera& camera, const Transform& T_world_camera, const RenderOptions& options = {});

 private:
  Workcell cell_;
  SettleResult settle_;
  std::unique_ptr<Renderer> renderer_;
  double clock_s_ = 0.0;
};

}  // namespace artisan::sim
