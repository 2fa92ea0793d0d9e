#pragma once
// The sensor server's wire protocol, version 1: length-prefixed binary frames over TCP, one
// request then its reply. Layouts, limits and the error policy are in sensors/PROTOCOL.md.
// Encoders build whole frames; decoders take a body and throw SensorError naming the field,
// never reading out of bounds.
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "artisan/sensors/sensor.hpp"

namespace artisan::sensors::protocol {

inline constexpr std::array<uint8_t, 4> kMagic = {'A', 'S', 'N', 'S'};
inline constexpr uint16_t kVersion = 1;
inline constexpr size_t kHeaderSize = 12;        ///< magic, version u16, type u16, body size u32
inline constexpr size_t kMaxStringBytes = 4096;  ///< any string in a request [bytes]
inline constexpr size_t kMaxParameters = 64;     ///< parameters in one ACQUIRE

enum class MessageType : uint16_t {
  // requests
  kList = 0x0001,
  kAcquire = 0x0002,
  kPanTiltGet = 0x0003,
  kPanTiltMove = 0x0004,
  kZoomGet = 0x0005,
  kZoomSet = 0x0006,
  kCancel = 0x0007,
  // replies
  kSensors = 0x8001,
  kAcquisition = 0x8002,
  kData = 0x8003,
  kPanTilt = 0x8004,
  kZoom = 0x8005,
  kCancelled = 0x8006,
  kError = 0x80FF,
};

struct FrameHeader {
  uint16_t version = kVersion;
  uint16_t type = 0;       ///< a MessageType, unchecked
  uint32_t body_size = 0;  ///< [bytes]
};

std::array<uint8_t, kHeaderSize> encode_header(MessageType type, uint32_t body_size);
/// Throws SensorError(kMalformedRequest) when the magic is wrong; judges nothing else.
FrameHeader decode_header(std::span<const uint8_t, kHeaderSize> bytes);

// --- requests --------------------------------------------------------------------------------

struct ListRequest {};
struct AcquireMessage {
  std::string sensor;
  AcquireRequest request;
  bool compress = true;  ///< deflate the .ari payload (smaller; costs time at both ends)
};
struct PanTiltGetRequest {
  std::string sensor;
};
struct PanTiltMoveRequest {
  std::string sensor;
  PanTiltState target;
};
struct ZoomGetRequest {
  std::string sensor;
};
struct ZoomSetRequest {
  std::string sensor;
  double fov_rad = 0.0;
};
struct CancelRequest {
  std::string sensor;
};
using Request = std::variant<ListRequest, AcquireMessage, PanTiltGetRequest, PanTiltMoveRequest, ZoomGetRequest, ZoomSetRequest,
                             CancelRequest>;

/// A whole request frame.
std::vector<uint8_t> encode_request(const Request& request);
/// A request's body. Throws SensorError(kMalformedRequest) for an unknown type, a truncated or
/// over-long body, an over-long string, too many parameters or a non-finite angle.
Request decode_request(uint16_t type, std::span<const uint8_t> body);
/// A whole frame as the server judges it: magic (kMalformedRequest), version
/// (kUnsupportedVersion), body size against `max_body_bytes` and the bytes present
/// (kRequestTooLarge, kMalformedRequest), then the body.
Request decode_request_frame(std::span<const uint8_t> frame, size_t max_body_bytes);

// --- replies ---------------------------------------------------------------------------------

/// An acquisition as it travels: the range image as .ari bytes (lossless, checksummed), the
/// environmental reading and the pan/tilt state.
struct EncodedAcquisition {
  bool has_range = false;
  std::vector<uint8_t> range_ari;  ///< io::encode_range_image(); empty without a range image
  std::optional<EnvironmentReading> environment;
  std::optional<PanTiltState> pan_tilt;
};

/// The ACQUISITION frame's body without the payload; `range_size` is announced, the bytes follow
/// in DATA frames.
struct AcquisitionHeader {
  bool has_range = false;
  uint64_t range_size = 0;  ///< [bytes]
  std::optional<EnvironmentReading> environment;
  std::optional<PanTiltState> pan_tilt;
};

struct ZoomState {
  double fov_rad = 0.0;
  ZoomLimits limits;
};

struct PanTiltReply {
  PanTiltState state;
  PanTiltLimits limits;
};

std::vector<uint8_t> encode_error(ErrorCode code, const std::string& message);
std::vector<uint8_t> encode_sensors(const std::vector<SensorDescription>& sensors);
std::vector<uint8_t> encode_acquisition_header(const AcquisitionHeader& header);
std::vector<uint8_t> encode_pan_tilt(const PanTiltReply& reply);
std::vector<uint8_t> encode_zoom(const ZoomState& zoom);
std::vector<uint8_t> encode_cancelled(uint32_t count);

/// Reply bodies; throw SensorError(kConnection) naming the field when malformed.
SensorError decode_error(std::span<const uint8_t> body);
std::vector<SensorDescription> decode_sensors(std::span<const uint8_t> body);
AcquisitionHeader decode_acquisition_header(std::span<const uint8_t> body);
PanTiltReply decode_pan_tilt(std::span<const uint8_t> body);
ZoomState decode_zoom(std::span<const uint8_t> body);
uint32_t decode_cancelled(std::span<const uint8_t> body);

/// The request's message type.
MessageType type_of(const Request& request);
/// The sensor a request names ("" for LIST).
const std::string& sensor_of(const Request& request);

}  // namespace artisan::sensors::protocol
