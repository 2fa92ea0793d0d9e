#pragma once
// Drivers by kind, and the set of sensors a server serves.
//
// A driver is a Sensor subclass; it becomes available by one line in builtin_drivers()
// (drivers.cpp) -- or, for a driver outside this library, one DriverRegistry::add() call.
// sensors/README.md shows how.
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "artisan/sensors/sensor.hpp"

namespace artisan::sensors {

class SimulatedWorkcell;

/// What a driver is made from.
struct DriverConfig {
  std::string name;  ///< the sensor's name on the server
  std::string kind;  ///< selects the driver
  std::shared_ptr<SimulatedWorkcell> workcell;  ///< simulated drivers: the workcell's one simulator
  std::filesystem::path folder;                 ///< replay: the folder of recordings
};

using DriverFactory = std::function<std::unique_ptr<Sensor>(const DriverConfig& config)>;

class DriverRegistry {
 public:
  /// Throws artisan::Error when the kind is registered already.
  void add(const std::string& kind, DriverFactory factory);
  /// Throws artisan::Error naming the kind and the known kinds when none is registered for it.
  std::unique_ptr<Sensor> create(const DriverConfig& config) const;
  std::vector<std::string> kinds() const;

 private:
  std::map<std::string, DriverFactory> factories_;
};

/// The drivers that ship with Artisan: "minolta-vivid-700", "pioneer-trinocular",
/// "environment" (simulated) and "replay" (recordings in a folder).
DriverRegistry builtin_drivers();

/// The sensors one server serves, by unique name.
class SensorSet {
 public:
  /// Throws artisan::Error when the name is taken.
  void add(std::unique_ptr<Sensor> sensor);
  /// Null when there is none.
  Sensor* find(const std::string& name) const;
  /// Throws SensorError(kUnknownSensor) naming the sensor and the ones served.
  Sensor& get(const std::string& name) const;
  std::vector<SensorDescription> describe() const;
  size_t size() const { return sensors_.size(); }

 private:
  std::vector<std::unique_ptr<Sensor>> sensors_;
};

/// One sensor for each sensor of the workcell, made by the registry's driver for its kind.
void add_workcell_sensors(SensorSet& set, const DriverRegistry& registry, const std::shared_ptr<SimulatedWorkcell>& workcell);

}  // namespace artisan::sensors
