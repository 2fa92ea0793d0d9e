#pragma once
// Simulated drivers: the Minolta Vivid 700, the Pioneer trinocular stereo head on its pan/tilt
// unit, and the environmental sensor, all driven by one sim::Simulator per workcell.
//
// The simulator (OSMesa, Bullet) is not thread-safe, so SimulatedWorkcell owns it on one
// worker thread: it is made there and only that thread touches it. Drivers queue jobs; a
// caller whose CancelToken fires stops waiting at once (a queued job is then skipped, a running
// one finishes and its result is dropped).
//
// Pan/tilt: a move checks the limits and records the target at once; the head is driven there
// (and the simulated clock advanced by the move time) by the simulator before the next
// acquisition with the Pioneer. Environment readings of a sensor mounted on the unit are taken
// at the recorded position.
//
// Zoom: the Vivid's lens (the model's zoom range, sim/vivid.hpp); a setting is checked and
// recorded at once and used by the next acquisitions of that sensor.
#include <condition_variable>
#include <map>
#include <deque>
#include <filesystem>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "artisan/sensors/sensor.hpp"
#include "artisan/sim/simulator.hpp"

namespace artisan::sensors {

class SimulatedWorkcell {
 public:
  /// Loads and settles the workcell on the worker thread. Throws what load_workcell() throws.
  explicit SimulatedWorkcell(const std::filesystem::path& workcell_file, const sim::LoadOptions& options = {});
  /// From a workcell already loaded (settled on the worker thread).
  explicit SimulatedWorkcell(sim::Workcell cell);
  /// Finishes the running job, fails queued ones with kShuttingDown, joins the worker.
  ~SimulatedWorkcell();
  SimulatedWorkcell(const SimulatedWorkcell&) = delete;
  SimulatedWorkcell& operator=(const SimulatedWorkcell&) = delete;

  /// The workcell's sensors as loaded.
  const std::vector<sim::SensorSpec>& sensors() const { return specs_; }
  const sim::SensorSpec& sensor(const std::string& name) const;  ///< throws SensorError(kUnknownSensor)
  const std::string& workcell_name() const { return workcell_name_; }

  /// The pan/tilt unit carrying `sensor`; throws SensorError(kNotSupported) when it has none.
  PanTiltLimits pan_tilt_limits(const std::string& sensor) const;
  PanTiltState pan_tilt(const std::string& sensor) const;
  /// Checks the limits (kOutOfLimits) and records the target (see the file comment).
  PanTiltState move_pan_tilt(const std::string& sensor, const PanTiltState& target);

  /// The zoom range of `sensor`'s lens; throws SensorError(kNotSupported) when it has none.
  ZoomLimits zoom_limits(const std::string& sensor) const;
  double fov(const std::string& sensor) const;
  /// Checks the zoom range (kOutOfLimits) and records the field of view [rad].
  double set_fov(const std::string& sensor, double fov_rad);

  /// An acquisition with a range sensor at the unit's recorded position and zoom. Throws SensorError.
  sim::Acquisition scan(const std::string& sensor, uint64_t seed, const CancelToken& cancel);
  /// A reading with an environment sensor at its mount (the unit's recorded position).
  sim::EnvironmentReading read_environment(const std::string& sensor, uint64_t seed, const CancelToken& cancel);

 private:
  struct Job {
    CancelToken cancel;
    std::function<void(sim::Simulator&)> work;
    std::promise<void> done;
  };
  void start(std::function<sim::Workcell()> load);
  void worker_loop(std::function<sim::Workcell()> load, std::promise<void> ready);
  /// Runs `work` on the worker; waits until it is done or `cancel` fires (then throws).
  void run(const std::string& what, const CancelToken& cancel, std::function<void(sim::Simulator&)> work);

  std::vector<sim::SensorSpec> specs_;
  std::string workcell_name_;
  sim::Workcell kinematics_;  ///< robots and sensors only, at the recorded joint values (guarded by mutex_)
  std::map<std::string, double> fov_rad_;  ///< recorded zoom settings by sensor (guarded by mutex_)
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::shared_ptr<Job>> queue_;
  bool stopping_ = false;
  std::thread worker_;
};

/// A simulated range sensor (Vivid 700 or Pioneer); pan/tilt when the workcell mounts it on a
/// unit; zoom for the Vivid.
class SimulatedRangeSensor : public Sensor, private PanTiltUnit {
 public:
  SimulatedRangeSensor(std::shared_ptr<SimulatedWorkcell> workcell, const std::string& name);
  SensorDescription describe() const override;
  PanTiltUnit* pan_tilt() override { return description_.pan_tilt ? this : nullptr; }
  ZoomControl* zoom() override { return description_.zoom ? &zoom_ : nullptr; }

 protected:
  Acquisition do_acquire(const AcquireRequest& request, const CancelToken& cancel) override;

 private:
  PanTiltLimits limits() const override;
  PanTiltState position() const override;
  PanTiltState move(const PanTiltState& target) override;

  class Zoom final : public ZoomControl {
   public:
    Zoom(SimulatedWorkcell& workcell, std::string sensor) : workcell_(workcell), sensor_(std::move(sensor)) {}
    ZoomLimits limits() const override { return workcell_.zoom_limits(sensor_); }
    double fov_rad() const override { return workcell_.fov(sensor_); }
    double set_fov_rad(double fov_rad) override { return workcell_.set_fov(sensor_, fov_rad); }

   private:
    SimulatedWorkcell& workcell_;
    std::string sensor_;
  };

  std::shared_ptr<SimulatedWorkcell> workcell_;
  SensorDescription description_;
  Zoom zoom_;
};

/// A simulated environmental sensor (gamma dose rate, temperature, humidity).
class SimulatedEnvironmentSensor : public Sensor {
 public:
  SimulatedEnvironmentSensor(std::shared_ptr<SimulatedWorkcell> workcell, const std::string& name);
  SensorDescription describe() const override { return description_; }

 protected:
  Acquisition do_acquire(const AcquireRequest& request, const CancelToken& cancel) override;

 private:
  std::shared_ptr<SimulatedWorkcell> workcell_;
  SensorDescription description_;
};

/// The driver's conversions, public so tests can check a direct simulator call against the server.
EnvironmentReading to_reading(const sim::EnvironmentReading& reading);
Acquisition to_acquisition(sim::Acquisition acquisition, const sim::SensorSpec& spec);

}  // namespace artisan::sensors
