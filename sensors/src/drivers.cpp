#include "artisan/sensors/drivers.hpp"

#include "artisan/sensors/replay.hpp"
#include "artisan/sensors/simulated.hpp"

namespace artisan::sensors {

namespace {

std::shared_ptr<SimulatedWorkcell> need_workcell(const DriverConfig& c) {
  if (!c.workcell) throw Error("sensor '" + c.name + "' (" + c.kind + "): a simulated driver needs a workcell (--workcell)");
  return c.workcell;
}

}  // namespace

DriverRegistry builtin_drivers() {
  DriverRegistry r;
  // One line per driver: kind -> how to make it.
  r.add("minolta-vivid-700", [](const DriverConfig& c) { return std::make_unique<SimulatedRangeSensor>(need_workcell(c), c.name); });
  r.add("pioneer-trinocular", [](const DriverConfig& c) { return std::make_unique<SimulatedRangeSensor>(need_workcell(c), c.name); });
  r.add("environment", [](const DriverConfig& c) { return std::make_unique<SimulatedEnvironmentSensor>(need_workcell(c), c.name); });
  r.add("replay", [](const DriverConfig& c) { return std::make_unique<ReplaySensor>(c.name, c.folder); });
  return r;
}

void DriverRegistry::add(const std::string& kind, DriverFactory factory) {
  if (!factories_.emplace(kind, std::move(factory)).second) throw Error("driver kind '" + kind + "' is registered twice");
}

std::unique_ptr<Sensor> DriverRegistry::create(const DriverConfig& config) const {
  const auto it = factories_.find(config.kind);
  if (it == factories_.end()) {
    std::string known;
    for (const auto& k : kinds()) known += (known.empty() ? "" : ", ") + k;
    throw Error("sensor '" + config.name + "': no driver for kind '" + config.kind + "' (drivers: " + known + ")");
  }
  return it->second(config);
}

std::vector<std::string> DriverRegistry::kinds() const {
  std::vector<std::string> out;
  for (const auto& [k, f] : factories_) out.push_back(k);
  return out;
}

void SensorSet::add(std::unique_ptr<Sensor> sensor) {
  const std::string name = sensor->describe().name;
  if (find(name)) throw Error("sensor name '" + name + "' is used twice");
  sensors_.push_back(std::move(sensor));
}

Sensor* SensorSet::find(const std::string& name) const {
  for (const auto& s : sensors_)
    if (s->describe().name == name) return s.get();
  return nullptr;
}

Sensor& SensorSet::get(const std::string& name) const {
  if (Sensor* s = find(name)) return *s;
  std::string known;
  for (const auto& s : sensors_) known += (known.empty() ? "" : ", ") + s->describe().name;
  throw SensorError(ErrorCode::kUnknownSensor, "no sensor '" + name + "' (this server has: " + (known.empty() ? "none" : known) + ")");
}

std::vector<SensorDescription> SensorSet::describe() const {
  std::vector<SensorDescription> out;
  for (const auto& s : sensors_) out.push_back(s->describe());
  return out;
}

void add_workcell_sensors(SensorSet& set, const DriverRegistry& registry, const std::shared_ptr<SimulatedWorkcell>& workcell) {
  for (const auto& s : workcell->sensors()) {
    DriverConfig c;
    c.name = s.name;
    c.kind = s.kind;
    c.workcell = workcell;
    set.add(registry.create(c));
  }
}

}  // namespace artisan::sensors
