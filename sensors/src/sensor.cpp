#include "artisan/sensors/sensor.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <sstream>

namespace artisan::sensors {

std::string to_string(ErrorCode code) {
  switch (code) {
    case ErrorCode::kMalformedRequest: return "malformed-request";
    case ErrorCode::kRequestTooLarge: return "request-too-large";
    case ErrorCode::kUnsupportedVersion: return "unsupported-version";
    case ErrorCode::kUnknownSensor: return "unknown-sensor";
    case ErrorCode::kBadParameter: return "bad-parameter";
    case ErrorCode::kOutOfLimits: return "out-of-limits";
    case ErrorCode::kNotSupported: return "not-supported";
    case ErrorCode::kSensorFailure: return "sensor-failure";
    case ErrorCode::kCancelled: return "cancelled";
    case ErrorCode::kTimeout: return "timeout";
    case ErrorCode::kBusy: return "busy";
    case ErrorCode::kShuttingDown: return "shutting-down";
    case ErrorCode::kInternal: return "internal";
    case ErrorCode::kConnection: return "connection";
  }
  return "error-" + std::to_string(static_cast<int>(code));
}

CancelToken::CancelToken() : state_(std::make_shared<State>()) {}

CancelToken::CancelToken(Clock::time_point deadline) : state_(std::make_shared<State>()) { state_->deadline = deadline; }

void CancelToken::cancel() const { state_->cancelled = true; }

bool CancelToken::cancelled() const { return state_->cancelled || Clock::now() >= state_->deadline; }

void CancelToken::check(const std::string& what) const {
  if (state_->cancelled) throw SensorError(ErrorCode::kCancelled, what + ": cancelled");
  if (Clock::now() >= state_->deadline) throw SensorError(ErrorCode::kTimeout, what + ": no answer within the deadline");
}

Acquisition Sensor::acquire(const AcquireRequest& request, const CancelToken& cancel) {
  const SensorDescription d = describe();
  check_parameters(d, request.params);
  if ((request.pan_rad || request.tilt_rad) && !d.pan_tilt)
    throw SensorError(ErrorCode::kNotSupported, "sensor '" + d.name + "' (" + d.kind + ") is not on a pan/tilt unit");
  {
    std::lock_guard lock(mutex_);
    active_.push_back(cancel);
  }
  const std::string what = "sensor '" + d.name + "'";
  // Registered while the driver works, so that cancel() reaches it; unregistered on every exit.
  struct Registration {
    Sensor& sensor;
    const CancelToken& token;
    ~Registration() {
      std::lock_guard lock(sensor.mutex_);
      std::erase_if(sensor.active_, [&](const CancelToken& t) { return t.same_as(token); });
    }
  } registration{*this, cancel};
  Acquisition result;
  try {
    cancel.check(what);
    result = do_acquire(request, cancel);
  } catch (const SensorError&) {
    throw;
  } catch (const std::exception& e) {
    throw SensorError(ErrorCode::kSensorFailure, what + " failed: " + e.what());
  }
  cancel.check(what);  // abandoned while the driver worked: the result is dropped
  return result;
}

int Sensor::cancel() {
  std::lock_guard lock(mutex_);
  for (const auto& t : active_) t.cancel();
  return static_cast<int>(active_.size());
}

namespace {

bool parses_as(const std::string& type, const std::string& value) {
  if (type == "integer") {
    if (value.empty()) return false;
    int64_t v = 0;
    const char* begin = value.data() + (value[0] == '+' ? 1 : 0);
    const auto [p, ec] = std::from_chars(begin, value.data() + value.size(), v);
    return ec == std::errc() && p == value.data() + value.size();
  }
  if (type == "number") {
    std::istringstream in(value);
    double v = 0;
    in >> v;
    return !in.fail() && in.eof() && std::isfinite(v);
  }
  return true;
}

const ParameterInfo* find_parameter(const SensorDescription& d, const std::string& name) {
  for (const auto& p : d.parameters)
    if (p.name == name) return &p;
  return nullptr;
}

}  // namespace

void check_parameters(const SensorDescription& d, const std::map<std::string, std::string>& params) {
  for (const auto& [name, value] : params) {
    const ParameterInfo* p = find_parameter(d, name);
    if (!p) {
      std::string known;
      for (const auto& q : d.parameters) known += (known.empty() ? "" : ", ") + q.name;
      throw SensorError(ErrorCode::kBadParameter, "sensor '" + d.name + "' has no parameter '" + name + "' (it has: " +
                                                      (known.empty() ? "none" : known) + ")");
    }
    if (!parses_as(p->type, value))
      throw SensorError(ErrorCode::kBadParameter,
                        "sensor '" + d.name + "': parameter '" + name + "' = '" + value + "' is not a valid " + p->type);
  }
}

std::string parameter_text(const SensorDescription& d, const std::map<std::string, std::string>& params, const std::string& name) {
  const auto it = params.find(name);
  if (it != params.end()) return it->second;
  const ParameterInfo* p = find_parameter(d, name);
  return p ? p->default_value : std::string();
}

uint64_t parameter_u64(const SensorDescription& d, const std::map<std::string, std::string>& params, const std::string& name) {
  const std::string text = parameter_text(d, params, name);
  if (text.empty()) return 0;
  int64_t v = 0;
  const char* begin = text.data() + (text[0] == '+' ? 1 : 0);
  const auto [p, ec] = std::from_chars(begin, text.data() + text.size(), v);
  if (ec != std::errc() || p != text.data() + text.size() || v < 0)
    throw SensorError(ErrorCode::kBadParameter, "sensor '" + d.name + "': parameter '" + name + "' = '" + text +
                                                    "' is not a non-negative integer");
  return static_cast<uint64_t>(v);
}

void check_pan_tilt(const std::string& sensor, const PanTiltLimits& limits, const PanTiltState& target) {
  const auto fail = [&](const char* axis, double value, double lo, double hi) {
    std::ostringstream os;
    os << "sensor '" << sensor << "': " << axis << " " << value << " rad is beyond the limits [" << lo << ", " << hi << "] rad";
    throw SensorError(ErrorCode::kOutOfLimits, os.str());
  };
  if (!std::isfinite(target.pan_rad) || target.pan_rad < limits.pan_min_rad - 1e-12 || target.pan_rad > limits.pan_max_rad + 1e-12)
    fail("pan", target.pan_rad, limits.pan_min_rad, limits.pan_max_rad);
  if (!std::isfinite(target.tilt_rad) || target.tilt_rad < limits.tilt_min_rad - 1e-12 || target.tilt_rad > limits.tilt_max_rad + 1e-12)
    fail("tilt", target.tilt_rad, limits.tilt_min_rad, limits.tilt_max_rad);
}

}  // namespace artisan::sensors
