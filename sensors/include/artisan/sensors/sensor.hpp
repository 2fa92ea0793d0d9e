#pragma once
// The sensor abstraction: every sensor -- simulated, replayed from files, or real -- behind one
// interface. A sensor describes itself (kind, parameters, optional capabilities), takes an
// acquisition on request and can be asked to abandon what it is doing. Optional capabilities a
// client discovers through the description: a pan/tilt unit, environmental readings, a zoom.
//
// Drivers implement do_acquire() (and the capability interfaces they have); Sensor::acquire()
// wraps it so that cancel() and deadlines work the same for every driver.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "artisan/core/error.hpp"
#include "artisan/core/pose.hpp"
#include "artisan/core/range_image.hpp"

namespace artisan::sensors {

/// Why a request failed. The numbers are part of the protocol (PROTOCOL.md) and never change.
enum class ErrorCode : uint16_t {
  kMalformedRequest = 1,    ///< the bytes are not a valid request (connection closed)
  kRequestTooLarge = 2,     ///< the request exceeds the server's maximum size (connection closed)
  kUnsupportedVersion = 3,  ///< the frame's protocol version is not served (connection closed)
  kUnknownSensor = 4,       ///< no sensor of that name
  kBadParameter = 5,        ///< an unknown parameter or an unparsable value
  kOutOfLimits = 6,         ///< e.g. a pan/tilt target beyond the unit's limits
  kNotSupported = 7,        ///< the sensor lacks the capability asked for
  kSensorFailure = 8,       ///< the driver failed while acquiring
  kCancelled = 9,           ///< cancel() was called, or the client went away
  kTimeout = 10,            ///< the driver did not answer within the deadline
  kBusy = 11,               ///< the server serves its maximum number of clients (connection closed)
  kShuttingDown = 12,       ///< the server is stopping (connection closed)
  kInternal = 13,           ///< a bug in the server
  kConnection = 100,        ///< client side only: the server cannot be reached or the connection broke
};

/// "malformed-request", "unknown-sensor", ...; "error-N" for a number not listed above.
std::string to_string(ErrorCode code);

/// A failed sensor request: a code a program can act on and a message a person can read.
class SensorError : public Error {
 public:
  SensorError(ErrorCode code, const std::string& message) : Error(message), code_(code) {}
  ErrorCode code() const { return code_; }

 private:
  ErrorCode code_;
};

/// Shared between an acquisition and whoever may abandon it (cancel(), a client that went away,
/// a deadline, shutdown). Copies share the state. Drivers poll it in any long wait.
class CancelToken {
 public:
  using Clock = std::chrono::steady_clock;
  /// Never expires; cancelled only by cancel().
  CancelToken();
  /// Expires at `deadline`.
  explicit CancelToken(Clock::time_point deadline);

  void cancel() const;
  /// True once cancel() was called or the deadline passed.
  bool cancelled() const;
  /// Throws SensorError(kCancelled) or (kTimeout), naming `what`, when cancelled() is true.
  void check(const std::string& what) const;
  /// True when both are copies of one token.
  bool same_as(const CancelToken& other) const { return state_ == other.state_; }

 private:
  struct State {
    std::atomic<bool> cancelled{false};
    Clock::time_point deadline = Clock::time_point::max();
  };
  std::shared_ptr<State> state_;
};

/// One parameter an acquisition accepts (`--param name=value` on the command line).
struct ParameterInfo {
  std::string name;
  std::string type;           ///< "integer", "number" or "string"
  std::string default_value;  ///< as text; empty = none
  std::string unit;           ///< e.g. "rad"; empty for none
  std::string description;
};

struct PanTiltLimits {
  double pan_min_rad = 0.0;       ///< [rad]
  double pan_max_rad = 0.0;       ///< [rad]
  double tilt_min_rad = 0.0;      ///< [rad]
  double tilt_max_rad = 0.0;      ///< [rad]
  double speed_rad_per_s = 0.0;   ///< slowest axis speed limit [rad/s]; 0 = unknown
};

struct PanTiltState {
  double pan_rad = 0.0;   ///< [rad]
  double tilt_rad = 0.0;  ///< [rad]
};

struct ZoomLimits {
  double min_fov_rad = 0.0;  ///< narrowest horizontal field of view [rad]
  double max_fov_rad = 0.0;  ///< widest horizontal field of view [rad]
};

/// One environmental reading, taken with an acquisition or alone.
struct EnvironmentReading {
  double time_s = 0.0;                            ///< [s since the epoch]
  Transform T_world_rig = Transform::Identity();  ///< where the rig was
  double dose_rate_uSv_per_h = 0.0;               ///< gamma dose rate [µSv/h]
  double temperature_C = 0.0;                     ///< [°C]
  double humidity_percent = 0.0;                  ///< relative humidity [%]
};

/// What a sensor is and what it can do; a client discovers capabilities from this.
struct SensorDescription {
  std::string name;          ///< unique on its server
  std::string kind;          ///< e.g. "minolta-vivid-700", "pioneer-trinocular", "environment", "replay"
  std::string description;   ///< one line for people
  bool range = false;        ///< acquisitions carry a range image
  bool environment = false;  ///< acquisitions carry an environmental reading
  std::optional<PanTiltLimits> pan_tilt;  ///< present when the sensor is on a pan/tilt unit
  std::optional<ZoomLimits> zoom;         ///< present when the sensor has a zoom
  std::vector<ParameterInfo> parameters;  ///< what acquire() accepts in AcquireRequest::params
};

struct AcquireRequest {
  std::map<std::string, std::string> params;  ///< by name, as text; checked against the description
  std::optional<double> pan_rad;   ///< pan/tilt sensors: move there first [rad]
  std::optional<double> tilt_rad;  ///< [rad]
};

/// One acquisition as a sensor delivers it (ground truth, where a simulator has it, stays
/// with the simulator: a real sensor has none).
struct Acquisition {
  std::optional<RangeImage> range;                ///< range sensors
  std::optional<EnvironmentReading> environment;  ///< readings taken with it
  std::optional<PanTiltState> pan_tilt;           ///< the head's position during the acquisition
};

/// Optional capability: a pan/tilt unit carrying the sensor.
class PanTiltUnit {
 public:
  virtual ~PanTiltUnit() = default;
  virtual PanTiltLimits limits() const = 0;
  virtual PanTiltState position() const = 0;
  /// Moves the head; throws SensorError(kOutOfLimits) naming the value and the limits.
  virtual PanTiltState move(const PanTiltState& target) = 0;
};

/// Optional capability: a zoom lens.
class ZoomControl {
 public:
  virtual ~ZoomControl() = default;
  virtual ZoomLimits limits() const = 0;
  virtual double fov_rad() const = 0;
  /// Throws SensorError(kOutOfLimits) naming the value and the limits.
  virtual double set_fov_rad(double fov_rad) = 0;
};

class Sensor {
 public:
  Sensor() = default;
  Sensor(const Sensor&) = delete;
  Sensor& operator=(const Sensor&) = delete;
  virtual ~Sensor() = default;

  virtual SensorDescription describe() const = 0;
  /// Takes one acquisition. Checks `request.params` against the description first
  /// (kBadParameter), then calls the driver. Throws SensorError: kCancelled or kTimeout when
  /// `cancel` fires or cancel() is called meanwhile, the driver's code, or kSensorFailure
  /// (with the driver's message) for any other exception.
  Acquisition acquire(const AcquireRequest& request, const CancelToken& cancel = CancelToken());
  /// Abandons every acquisition of this sensor in progress or queued; returns how many.
  int cancel();

  /// Capabilities: null when the sensor has none.
  virtual PanTiltUnit* pan_tilt() { return nullptr; }
  virtual ZoomControl* zoom() { return nullptr; }

 protected:
  /// The driver's acquisition. `request.params` hold only described names, with values that
  /// parse as their type. Poll `cancel` in any long wait.
  virtual Acquisition do_acquire(const AcquireRequest& request, const CancelToken& cancel) = 0;

 private:
  std::mutex mutex_;
  std::vector<CancelToken> active_;
};

/// Throws SensorError(kBadParameter) naming the sensor, the parameter and the value when a
/// name is not described or a value does not parse as its type.
void check_parameters(const SensorDescription& description, const std::map<std::string, std::string>& params);
/// The value of an integer parameter, or its default (0 when it has none).
uint64_t parameter_u64(const SensorDescription& description, const std::map<std::string, std::string>& params,
                       const std::string& name);
/// The value of a parameter as text, or its default.
std::string parameter_text(const SensorDescription& description, const std::map<std::string, std::string>& params,
                           const std::string& name);
/// Throws SensorError(kOutOfLimits) naming the sensor, the values and the limits.
void check_pan_tilt(const std::string& sensor, const PanTiltLimits& limits, const PanTiltState& target);

}  // namespace artisan::sensors
