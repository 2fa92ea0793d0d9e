#include "artisan/sensors/simulated.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "artisan/sim/physics.hpp"
#include "artisan/sim/vivid.hpp"

namespace artisan::sensors {

namespace {

const std::vector<ParameterInfo> kSeedParameter = {
    {"seed", "integer", "0", "", "noise seed: the same seed and simulator state give identical data"}};

}  // namespace

SimulatedWorkcell::SimulatedWorkcell(const std::filesystem::path& file, const sim::LoadOptions& options) {
  start([file, options] { return sim::load_workcell(file, options); });
}

SimulatedWorkcell::SimulatedWorkcell(sim::Workcell cell) {
  auto shared = std::make_shared<sim::Workcell>(std::move(cell));
  start([shared] { return std::move(*shared); });
}

void SimulatedWorkcell::start(std::function<sim::Workcell()> load) {
  std::promise<void> ready;
  auto ready_future = ready.get_future();
  worker_ = std::thread(&SimulatedWorkcell::worker_loop, this, std::move(load), std::move(ready));
  try {
    ready_future.get();
  } catch (...) {
    worker_.join();
    throw;
  }
}

SimulatedWorkcell::~SimulatedWorkcell() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (worker_.joinable()) worker_.join();
}

void SimulatedWorkcell::worker_loop(std::function<sim::Workcell()> load, std::promise<void> ready) {
  std::unique_ptr<sim::Simulator> simulator;
  try {
    simulator = std::make_unique<sim::Simulator>(load());
    const sim::Workcell& cell = simulator->workcell();
    specs_ = cell.sensors;
    workcell_name_ = cell.name;
    kinematics_.source = cell.source;
    kinematics_.name = cell.name;
    kinematics_.robots = cell.robots;
    kinematics_.sensors = cell.sensors;
    ready.set_value();
  } catch (...) {
    ready.set_exception(std::current_exception());
    return;
  }
  for (;;) {
    std::shared_ptr<Job> job;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) {
        for (auto& j : queue_)
          j->done.set_exception(std::make_exception_ptr(SensorError(ErrorCode::kShuttingDown, "simulated workcell: shutting down")));
        queue_.clear();
        return;
      }
      job = std::move(queue_.front());
      queue_.pop_front();
    }
    if (job->cancel.cancelled()) {  // nobody waits for it any more
      job->done.set_exception(std::make_exception_ptr(SensorError(ErrorCode::kCancelled, "simulated workcell: cancelled")));
      continue;
    }
    try {
      job->work(*simulator);
      job->done.set_value();
    } catch (...) {
      job->done.set_exception(std::current_exception());
    }
  }
}

void SimulatedWorkcell::run(const std::string& what, const CancelToken& cancel, std::function<void(sim::Simulator&)> work) {
  auto job = std::make_shared<Job>();
  job->cancel = cancel;
  job->work = std::move(work);
  auto done = job->done.get_future();
  {
    std::lock_guard lock(mutex_);
    if (stopping_) throw SensorError(ErrorCode::kShuttingDown, what + ": the simulated workcell is shutting down");
    queue_.push_back(job);
  }
  wake_.notify_one();
  while (done.wait_for(std::chrono::milliseconds(10)) != std::future_status::ready) cancel.check(what);
  done.get();
}

const sim::SensorSpec& SimulatedWorkcell::sensor(const std::string& name) const {
  for (const auto& s : specs_)
    if (s.name == name) return s;
  throw SensorError(ErrorCode::kUnknownSensor, "workcell '" + workcell_name_ + "' has no sensor '" + name + "'");
}

PanTiltLimits SimulatedWorkcell::pan_tilt_limits(const std::string& name) const {
  const sim::SensorSpec& s = sensor(name);
  if (s.pan_tilt_robot.empty()) throw SensorError(ErrorCode::kNotSupported, "sensor '" + name + "' is not on a pan/tilt unit");
  std::lock_guard lock(mutex_);
  const sim::Robot& ptu = kinematics_.robot(s.pan_tilt_robot);
  const sim::JointSpec& pan = ptu.joint(s.pan_joint);
  const sim::JointSpec& tilt = ptu.joint(s.tilt_joint);
  PanTiltLimits l;
  l.pan_min_rad = pan.lower;
  l.pan_max_rad = pan.upper;
  l.tilt_min_rad = tilt.lower;
  l.tilt_max_rad = tilt.upper;
  l.speed_rad_per_s = std::min(pan.velocity, tilt.velocity);
  return l;
}

PanTiltState SimulatedWorkcell::pan_tilt(const std::string& name) const {
  const sim::SensorSpec& s = sensor(name);
  if (s.pan_tilt_robot.empty()) throw SensorError(ErrorCode::kNotSupported, "sensor '" + name + "' is not on a pan/tilt unit");
  std::lock_guard lock(mutex_);
  const sim::Robot& ptu = kinematics_.robot(s.pan_tilt_robot);
  const auto value = [&](const std::string& j) {
    const auto it = ptu.joint_values.find(j);
    return it == ptu.joint_values.end() ? 0.0 : it->second;
  };
  return {value(s.pan_joint), value(s.tilt_joint)};
}

PanTiltState SimulatedWorkcell::move_pan_tilt(const std::string& name, const PanTiltState& target) {
  check_pan_tilt(name, pan_tilt_limits(name), target);
  const sim::SensorSpec& s = sensor(name);
  std::lock_guard lock(mutex_);
  kinematics_.set_joint(s.pan_tilt_robot, s.pan_joint, target.pan_rad);
  kinematics_.set_joint(s.pan_tilt_robot, s.tilt_joint, target.tilt_rad);
  return target;
}

ZoomLimits SimulatedWorkcell::zoom_limits(const std::string& name) const {
  const sim::SensorSpec& s = sensor(name);
  if (s.kind != "minolta-vivid-700") throw SensorError(ErrorCode::kNotSupported, "sensor '" + name + "' (" + s.kind + ") has no zoom");
  const sim::VividParams p = sim::vivid_params(s.params);
  return {p.min_fov_rad, p.max_fov_rad};
}

double SimulatedWorkcell::fov(const std::string& name) const {
  zoom_limits(name);  // has a zoom
  std::lock_guard lock(mutex_);
  const auto it = fov_rad_.find(name);
  return it != fov_rad_.end() ? it->second : sim::vivid_params(sensor(name).params).horizontal_fov_rad;
}

double SimulatedWorkcell::set_fov(const std::string& name, double fov_rad) {
  const ZoomLimits l = zoom_limits(name);
  if (!(std::isfinite(fov_rad) && fov_rad >= l.min_fov_rad && fov_rad <= l.max_fov_rad))
    throw SensorError(ErrorCode::kOutOfLimits, "sensor '" + name + "': field of view " + std::to_string(fov_rad) + " rad is outside its zoom range [" +
                                                   std::to_string(l.min_fov_rad) + ", " + std::to_string(l.max_fov_rad) + "] rad");
  std::lock_guard lock(mutex_);
  fov_rad_[name] = fov_rad;
  return fov_rad;
}

sim::Acquisition SimulatedWorkcell::scan(const std::string& name, uint64_t seed, const CancelToken& cancel) {
  const sim::SensorSpec& s = sensor(name);
  sim::ScanRequest req;
  req.sensor = name;
  req.seed = seed;
  {
    std::lock_guard lock(mutex_);
    const auto zoomed = fov_rad_.find(name);
    if (zoomed != fov_rad_.end()) req.horizontal_fov_rad = zoomed->second;
  }
  if (!s.pan_tilt_robot.empty()) {
    const PanTiltState at = pan_tilt(name);
    req.pan_rad = at.pan_rad;
    req.tilt_rad = at.tilt_rad;
  }
  // Shared: a caller that stops waiting (cancelled) must not leave the job a dangling reference.
  auto out = std::make_shared<sim::Acquisition>();
  run("sensor '" + name + "'", cancel, [out, req](sim::Simulator& simulator) { *out = simulator.scan(req); });
  return std::move(*out);
}

sim::EnvironmentReading SimulatedWorkcell::read_environment(const std::string& name, uint64_t seed, const CancelToken& cancel) {
  const sim::SensorSpec& s = sensor(name);
  Transform T_world_rig;
  {
    std::lock_guard lock(mutex_);
    T_world_rig = kinematics_.T_world_sensor(s);
  }
  auto out = std::make_shared<sim::EnvironmentReading>();
  run("sensor '" + name + "'", cancel,
      [out, name, T_world_rig, seed](sim::Simulator& simulator) { *out = simulator.read_environment(name, T_world_rig, seed); });
  return *out;
}

EnvironmentReading to_reading(const sim::EnvironmentReading& r) {
  return {r.time_s, r.T_world_rig, r.dose_rate_uSv_per_h, r.temperature_C, r.humidity_percent};
}

Acquisition to_acquisition(sim::Acquisition acq, const sim::SensorSpec& spec) {
  Acquisition out;
  if (acq.truth.environment) out.environment = to_reading(*acq.truth.environment);
  if (!spec.pan_tilt_robot.empty()) {
    const auto& j = acq.truth.joint_values;
    const auto pan = j.find(spec.pan_joint), tilt = j.find(spec.tilt_joint);
    out.pan_tilt = PanTiltState{pan == j.end() ? 0.0 : pan->second, tilt == j.end() ? 0.0 : tilt->second};
  }
  out.range = std::move(acq.range);
  return out;
}

// --- range sensors ---------------------------------------------------------------------------

SimulatedRangeSensor::SimulatedRangeSensor(std::shared_ptr<SimulatedWorkcell> workcell, const std::string& name)
    : workcell_(std::move(workcell)), zoom_(*workcell_, name) {
  const sim::SensorSpec& s = workcell_->sensor(name);
  description_.name = s.name;
  description_.kind = s.kind;
  description_.range = true;
  for (const auto& e : workcell_->sensors()) description_.environment |= e.kind == "environment";
  if (s.kind == "minolta-vivid-700")
    description_.description = "simulated Minolta Vivid 700 laser stripe scanner: 200 x 200 range, 400 x 400 colour (workcell '" +
                               workcell_->workcell_name() + "')";
  else if (s.kind == "pioneer-trinocular")
    description_.description = "simulated Pioneer trinocular stereo head: three 640 x 480 cameras, SGBM stereo (workcell '" +
                               workcell_->workcell_name() + "')";
  else
    throw Error("sensor '" + name + "' is a " + s.kind + " sensor, not a simulated range sensor");
  if (!s.pan_tilt_robot.empty()) description_.pan_tilt = workcell_->pan_tilt_limits(name);
  if (s.kind == "minolta-vivid-700") description_.zoom = workcell_->zoom_limits(name);
  description_.parameters = kSeedParameter;
}

SensorDescription SimulatedRangeSensor::describe() const { return description_; }

Acquisition SimulatedRangeSensor::do_acquire(const AcquireRequest& request, const CancelToken& cancel) {
  if (request.pan_rad || request.tilt_rad) {
    PanTiltState target = position();
    if (request.pan_rad) target.pan_rad = *request.pan_rad;
    if (request.tilt_rad) target.tilt_rad = *request.tilt_rad;
    move(target);
  }
  const uint64_t seed = parameter_u64(description_, request.params, "seed");
  return to_acquisition(workcell_->scan(description_.name, seed, cancel), workcell_->sensor(description_.name));
}

PanTiltLimits SimulatedRangeSensor::limits() const { return workcell_->pan_tilt_limits(description_.name); }
PanTiltState SimulatedRangeSensor::position() const { return workcell_->pan_tilt(description_.name); }
PanTiltState SimulatedRangeSensor::move(const PanTiltState& target) { return workcell_->move_pan_tilt(description_.name, target); }

// --- environment -----------------------------------------------------------------------------

SimulatedEnvironmentSensor::SimulatedEnvironmentSensor(std::shared_ptr<SimulatedWorkcell> workcell, const std::string& name)
    : workcell_(std::move(workcell)) {
  const sim::SensorSpec& s = workcell_->sensor(name);
  if (s.kind != "environment") throw Error("sensor '" + name + "' is a " + s.kind + " sensor, not an environment sensor");
  description_.name = s.name;
  description_.kind = s.kind;
  description_.environment = true;
  description_.description = "simulated environmental sensor: gamma dose rate, temperature, humidity (workcell '" +
                             workcell_->workcell_name() + "', mount " + s.mount + ")";
  description_.parameters = kSeedParameter;
}

Acquisition SimulatedEnvironmentSensor::do_acquire(const AcquireRequest& request, const CancelToken& cancel) {
  const uint64_t seed = parameter_u64(description_, request.params, "seed");
  Acquisition out;
  out.environment = to_reading(workcell_->read_environment(description_.name, seed, cancel));
  return out;
}

}  // namespace artisan::sensors
