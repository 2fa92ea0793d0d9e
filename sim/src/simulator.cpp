#include "artisan/sim/simulator.hpp"

#include <cmath>

#include "artisan/core/error.hpp"
#include "artisan/sim/environment.hpp"
#include "artisan/sim/pioneer.hpp"
#include "artisan/sim/vivid.hpp"

namespace artisan::sim {

Simulator::Simulator(Workcell cell, const SettleParams& settle_params) : cell_(std::move(cell)) {
  settle_ = settle(cell_, settle_params);
  renderer_ = std::make_unique<Renderer>(cell_);
  clock_s_ = cell_.start_time_s;
}

Simulator::~Simulator() = default;

RenderResult Simulator::render(const PinholeCamera& camera, const Transform& T_world_camera, const RenderOptions& options) {
  return renderer_->render(cell_, camera, T_world_camera, options);
}

EnvironmentReading Simulator::read_environment(const std::string& name, const std::optional<Transform>& T_world_rig, uint64_t seed) {
  const SensorSpec& s = cell_.sensor(name);
  if (s.kind != "environment") throw Error("sensor '" + name + "' is a " + s.kind + ", not an environment sensor");
  return sim::read_environment(cell_, T_world_rig ? *T_world_rig : cell_.T_world_sensor(s), clock_s_, environment_params(s.params), seed);
}

Acquisition Simulator::scan(const ScanRequest& req) {
  const SensorSpec& s = cell_.sensor(req.sensor);
  std::map<std::string, double> joints;
  if (req.pan_rad || req.tilt_rad) {
    if (s.pan_tilt_robot.empty())
      throw Error("sensor '" + s.name + "' (" + s.kind + ") is not on a pan/tilt unit: --pan/--tilt do not apply");
    if (req.T_world_sensor) throw Error("sensor '" + s.name + "': give a pose or pan/tilt angles, not both");
    const Robot& ptu = cell_.robot(s.pan_tilt_robot);
    const auto value = [&](const std::string& j) {
      const auto it = ptu.joint_values.find(j);
      return it == ptu.joint_values.end() ? 0.0 : it->second;
    };
    const double pan0 = value(s.pan_joint), tilt0 = value(s.tilt_joint);
    const double pan = req.pan_rad.value_or(pan0), tilt = req.tilt_rad.value_or(tilt0);
    cell_.set_joint(ptu.name, s.pan_joint, pan);  // throws beyond the limits
    cell_.set_joint(ptu.name, s.tilt_joint, tilt);
    cell_.update_robot_poses();
    // The move takes the slower axis's time at the joints' speed limits.
    const double v_pan = ptu.joint(s.pan_joint).velocity, v_tilt = ptu.joint(s.tilt_joint).velocity;
    double move = 0.0;
    if (v_pan > 0) move = std::max(move, std::abs(pan - pan0) / v_pan);
    if (v_tilt > 0) move = std::max(move, std::abs(tilt - tilt0) / v_tilt);
    clock_s_ += move;
  }
  if (!s.pan_tilt_robot.empty()) {
    const Robot& ptu = cell_.robot(s.pan_tilt_robot);
    for (const auto& j : {s.pan_joint, s.tilt_joint}) {
      const auto it = ptu.joint_values.find(j);
      joints[j] = it == ptu.joint_values.end() ? 0.0 : it->second;
    }
  }
  const Transform T_world_sensor = req.T_world_sensor ? *req.T_world_sensor : cell_.T_world_sensor(s);
  Acquisition acq;
  if (s.kind == "minolta-vivid-700") {
    VividParams p = vivid_params(s.params);
    if (req.horizontal_fov_rad) {
      const double fov = *req.horizontal_fov_rad;
      if (!(fov >= p.min_fov_rad && fov <= p.max_fov_rad))
        throw Error("sensor '" + s.name + "': field of view " + std::to_string(fov) + " rad is outside its zoom range [" +
                    std::to_string(p.min_fov_rad) + ", " + std::to_string(p.max_fov_rad) + "] rad");
      p.horizontal_fov_rad = fov;
    }
    acq = scan_vivid(*renderer_, cell_, T_world_sensor, p, req.seed);
    acq.range.sensor.timestamp_s = clock_s_;
    clock_s_ += p.scan_time_s;
  } else if (s.kind == "pioneer-trinocular") {
    if (req.horizontal_fov_rad) throw Error("sensor '" + s.name + "' (" + s.kind + ") has fixed lenses: no zoom");
    const PioneerParams p = pioneer_params(s.params);
    clock_s_ += joints.empty() ? 0.0 : p.settle_time_s;
    acq = scan_pioneer(*renderer_, cell_, T_world_sensor, p, req.seed);
    acq.range.sensor.timestamp_s = clock_s_;
  } else {
    throw Error("sensor '" + s.name + "' is an " + s.kind + " sensor, not a range sensor: it cannot scan");
  }
  acq.range.sensor.name = s.name;
  acq.truth.sensor_name = s.name;
  acq.truth.time_s = acq.range.sensor.timestamp_s;
  acq.truth.joint_values = joints;
  // Environmental sensors aboard the rig read at the same time and place.
  for (const auto& e : cell_.sensors) {
    if (e.kind != "environment") continue;
    acq.truth.environment = sim::read_environment(cell_, T_world_sensor, acq.truth.time_s, environment_params(e.params), req.seed);
    const auto& r = *acq.truth.environment;
    acq.range.sensor.attributes["dose_rate_uSv_per_h"] = std::to_string(r.dose_rate_uSv_per_h);
    acq.range.sensor.attributes["temperature_C"] = std::to_string(r.temperature_C);
    acq.range.sensor.attributes["humidity_percent"] = std::to_string(r.humidity_percent);
    break;
  }
  for (const auto& [j, q] : joints) acq.range.sensor.attributes[j + "_rad"] = std::to_string(q);
  return acq;
}

}  // namespace artisan::sim
