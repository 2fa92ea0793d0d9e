#include "artisan/sensors/protocol.hpp"

#include <cmath>
#include <cstring>

#include "artisan/core/io/bytes.hpp"

namespace artisan::sensors::protocol {

namespace {

using io::ByteReader;
using io::ByteWriter;

// Decoding errors: a request's defects are the client's (kMalformedRequest); a reply's are a
// broken server or link (kConnection).
template <typename Fn>
auto decoding(ErrorCode code, const std::string& what, Fn&& fn) {
  try {
    return fn();
  } catch (const SensorError&) {
    throw;
  } catch (const Error& e) {
    throw SensorError(code, what + ": " + e.what());
  }
}

std::vector<uint8_t> frame(MessageType type, ByteWriter& body) {
  const auto header = encode_header(type, static_cast<uint32_t>(body.bytes().size()));
  std::vector<uint8_t> out(kHeaderSize + body.bytes().size());
  std::memcpy(out.data(), header.data(), kHeaderSize);
  if (!body.bytes().empty()) std::memcpy(out.data() + kHeaderSize, body.bytes().data(), body.bytes().size());
  return out;
}

void put_transform(ByteWriter& w, const Transform& T) {
  for (double v : to_row_major(T)) w.put<double>(v);
}

Transform get_transform(ByteReader& r, const char* field) {
  std::array<double, 16> m{};
  for (double& v : m) v = r.get<double>(field);
  return from_row_major(m);
}

double get_finite(ByteReader& r, const char* field) {
  const double v = r.get<double>(field);
  if (!std::isfinite(v)) r.fail(field, "not a finite number");
  return v;
}

void expect_end(const ByteReader& r) {
  if (r.remaining() != 0) r.fail("end", std::to_string(r.remaining()) + " unexpected trailing bytes");
}

void put_environment(ByteWriter& w, const EnvironmentReading& e) {
  w.put<double>(e.time_s);
  put_transform(w, e.T_world_rig);
  w.put<double>(e.dose_rate_uSv_per_h);
  w.put<double>(e.temperature_C);
  w.put<double>(e.humidity_percent);
}

EnvironmentReading get_environment(ByteReader& r) {
  EnvironmentReading e;
  e.time_s = r.get<double>("environment.time_s");
  e.T_world_rig = get_transform(r, "environment.T_world_rig");
  e.dose_rate_uSv_per_h = r.get<double>("environment.dose_rate_uSv_per_h");
  e.temperature_C = r.get<double>("environment.temperature_C");
  e.humidity_percent = r.get<double>("environment.humidity_percent");
  return e;
}

void put_limits(ByteWriter& w, const PanTiltLimits& l) {
  w.put<double>(l.pan_min_rad);
  w.put<double>(l.pan_max_rad);
  w.put<double>(l.tilt_min_rad);
  w.put<double>(l.tilt_max_rad);
  w.put<double>(l.speed_rad_per_s);
}

PanTiltLimits get_limits(ByteReader& r) {
  PanTiltLimits l;
  l.pan_min_rad = r.get<double>("pan_tilt.pan_min_rad");
  l.pan_max_rad = r.get<double>("pan_tilt.pan_max_rad");
  l.tilt_min_rad = r.get<double>("pan_tilt.tilt_min_rad");
  l.tilt_max_rad = r.get<double>("pan_tilt.tilt_max_rad");
  l.speed_rad_per_s = r.get<double>("pan_tilt.speed_rad_per_s");
  return l;
}

}  // namespace

std::array<uint8_t, kHeaderSize> encode_header(MessageType type, uint32_t body_size) {
  std::array<uint8_t, kHeaderSize> h{};
  std::memcpy(h.data(), kMagic.data(), 4);
  const uint16_t version = kVersion, t = static_cast<uint16_t>(type);
  std::memcpy(h.data() + 4, &version, 2);
  std::memcpy(h.data() + 6, &t, 2);
  std::memcpy(h.data() + 8, &body_size, 4);
  return h;
}

FrameHeader decode_header(std::span<const uint8_t, kHeaderSize> bytes) {
  if (std::memcmp(bytes.data(), kMagic.data(), 4) != 0)
    throw SensorError(ErrorCode::kMalformedRequest, "frame header: bad magic (not the Artisan sensor protocol)");
  FrameHeader h;
  std::memcpy(&h.version, bytes.data() + 4, 2);
  std::memcpy(&h.type, bytes.data() + 6, 2);
  std::memcpy(&h.body_size, bytes.data() + 8, 4);
  return h;
}

MessageType type_of(const Request& request) {
  struct V {
    MessageType operator()(const ListRequest&) const { return MessageType::kList; }
    MessageType operator()(const AcquireMessage&) const { return MessageType::kAcquire; }
    MessageType operator()(const PanTiltGetRequest&) const { return MessageType::kPanTiltGet; }
    MessageType operator()(const PanTiltMoveRequest&) const { return MessageType::kPanTiltMove; }
    MessageType operator()(const ZoomGetRequest&) const { return MessageType::kZoomGet; }
    MessageType operator()(const ZoomSetRequest&) const { return MessageType::kZoomSet; }
    MessageType operator()(const CancelRequest&) const { return MessageType::kCancel; }
  };
  return std::visit(V{}, request);
}

const std::string& sensor_of(const Request& request) {
  static const std::string none;
  return std::visit(
      [](const auto& r) -> const std::string& {
        if constexpr (std::is_same_v<std::decay_t<decltype(r)>, ListRequest>) return none;
        else return r.sensor;
      },
      request);
}

std::vector<uint8_t> encode_request(const Request& request) {
  ByteWriter w;
  std::visit(
      [&](const auto& r) {
        using T = std::decay_t<decltype(r)>;
        if constexpr (!std::is_same_v<T, ListRequest>) w.put_string(r.sensor);
        if constexpr (std::is_same_v<T, AcquireMessage>) {
          const uint8_t flags = (r.request.pan_rad ? 1 : 0) | (r.request.tilt_rad ? 2 : 0) | (r.compress ? 4 : 0);
          w.put<uint8_t>(flags);
          w.put<double>(r.request.pan_rad.value_or(0.0));
          w.put<double>(r.request.tilt_rad.value_or(0.0));
          w.put<uint32_t>(static_cast<uint32_t>(r.request.params.size()));
          for (const auto& [k, v] : r.request.params) {
            w.put_string(k);
            w.put_string(v);
          }
        } else if constexpr (std::is_same_v<T, PanTiltMoveRequest>) {
          w.put<double>(r.target.pan_rad);
          w.put<double>(r.target.tilt_rad);
        } else if constexpr (std::is_same_v<T, ZoomSetRequest>) {
          w.put<double>(r.fov_rad);
        }
      },
      request);
  return frame(type_of(request), w);
}

Request decode_request(uint16_t type, std::span<const uint8_t> body) {
  return decoding(ErrorCode::kMalformedRequest, "request", [&]() -> Request {
    ByteReader r(body, "request type " + std::to_string(type));
    const auto sensor = [&] { return r.get_string("sensor", kMaxStringBytes); };
    Request out;
    switch (static_cast<MessageType>(type)) {
      case MessageType::kList: out = ListRequest{}; break;
      case MessageType::kAcquire: {
        AcquireMessage m;
        m.sensor = sensor();
        const auto flags = r.get<uint8_t>("flags");
        if (flags & ~uint8_t{7}) r.fail("flags", "unknown bits " + std::to_string(flags));
        const double pan = get_finite(r, "pan_rad"), tilt = get_finite(r, "tilt_rad");
        if (flags & 1) m.request.pan_rad = pan;
        if (flags & 2) m.request.tilt_rad = tilt;
        m.compress = (flags & 4) != 0;
        const auto n = r.get<uint32_t>("parameter count");
        if (n > kMaxParameters) r.fail("parameter count", std::to_string(n) + " exceeds " + std::to_string(kMaxParameters));
        for (uint32_t i = 0; i < n; ++i) {
          std::string k = r.get_string("parameter name", kMaxStringBytes);
          std::string v = r.get_string("parameter value", kMaxStringBytes);
          if (!m.request.params.emplace(std::move(k), std::move(v)).second) r.fail("parameter name", "given twice");
        }
        out = std::move(m);
        break;
      }
      case MessageType::kPanTiltGet: out = PanTiltGetRequest{sensor()}; break;
      case MessageType::kPanTiltMove: {
        PanTiltMoveRequest m{sensor(), {}};
        m.target.pan_rad = get_finite(r, "pan_rad");
        m.target.tilt_rad = get_finite(r, "tilt_rad");
        out = std::move(m);
        break;
      }
      case MessageType::kZoomGet: out = ZoomGetRequest{sensor()}; break;
      case MessageType::kZoomSet: {
        ZoomSetRequest m{sensor(), 0.0};
        m.fov_rad = get_finite(r, "fov_rad");
        out = std::move(m);
        break;
      }
      case MessageType::kCancel: out = CancelRequest{sensor()}; break;
      default: throw SensorError(ErrorCode::kMalformedRequest, "request: unknown message type " + std::to_string(type));
    }
    expect_end(r);
    return out;
  });
}

Request decode_request_frame(std::span<const uint8_t> bytes, size_t max_body_bytes) {
  if (bytes.size() < kHeaderSize)
    throw SensorError(ErrorCode::kMalformedRequest, "request: " + std::to_string(bytes.size()) + " bytes, shorter than a frame header");
  const FrameHeader h = decode_header(bytes.first<kHeaderSize>());
  if (h.version != kVersion)
    throw SensorError(ErrorCode::kUnsupportedVersion,
                      "request: protocol version " + std::to_string(h.version) + " (this server speaks " + std::to_string(kVersion) + ")");
  if (h.body_size > max_body_bytes)
    throw SensorError(ErrorCode::kRequestTooLarge,
                      "request: body of " + std::to_string(h.body_size) + " bytes exceeds the limit of " + std::to_string(max_body_bytes));
  if (h.body_size != bytes.size() - kHeaderSize)
    throw SensorError(ErrorCode::kMalformedRequest, "request: header announces " + std::to_string(h.body_size) + " body bytes, " +
                                                        std::to_string(bytes.size() - kHeaderSize) + " present");
  return decode_request(h.type, bytes.subspan(kHeaderSize));
}

// --- replies ---------------------------------------------------------------------------------

std::vector<uint8_t> encode_error(ErrorCode code, const std::string& message) {
  ByteWriter w;
  w.put<uint16_t>(static_cast<uint16_t>(code));
  w.put_string(message.size() > kMaxStringBytes ? message.substr(0, kMaxStringBytes) : message);
  return frame(MessageType::kError, w);
}

SensorError decode_error(std::span<const uint8_t> body) {
  return decoding(ErrorCode::kConnection, "error reply", [&] {
    ByteReader r(body, "error reply");
    const auto code = static_cast<ErrorCode>(r.get<uint16_t>("code"));
    std::string message = r.get_string("message", kMaxStringBytes);
    expect_end(r);
    return SensorError(code, message);
  });
}

std::vector<uint8_t> encode_sensors(const std::vector<SensorDescription>& sensors) {
  ByteWriter w;
  w.put<uint32_t>(static_cast<uint32_t>(sensors.size()));
  for (const auto& s : sensors) {
    w.put_string(s.name);
    w.put_string(s.kind);
    w.put_string(s.description);
    const uint8_t flags = (s.range ? 1 : 0) | (s.environment ? 2 : 0) | (s.pan_tilt ? 4 : 0) | (s.zoom ? 8 : 0);
    w.put<uint8_t>(flags);
    if (s.pan_tilt) put_limits(w, *s.pan_tilt);
    if (s.zoom) {
      w.put<double>(s.zoom->min_fov_rad);
      w.put<double>(s.zoom->max_fov_rad);
    }
    w.put<uint32_t>(static_cast<uint32_t>(s.parameters.size()));
    for (const auto& p : s.parameters) {
      w.put_string(p.name);
      w.put_string(p.type);
      w.put_string(p.default_value);
      w.put_string(p.unit);
      w.put_string(p.description);
    }
  }
  return frame(MessageType::kSensors, w);
}

std::vector<SensorDescription> decode_sensors(std::span<const uint8_t> body) {
  return decoding(ErrorCode::kConnection, "sensor list reply", [&] {
    ByteReader r(body, "sensor list reply");
    const auto n = r.get<uint32_t>("sensor count");
    // A description takes at least 17 bytes (3 strings, flags, parameter count): bound the allocation.
    if (n > r.remaining() / 17) r.fail("sensor count", std::to_string(n) + " is more than the reply can hold");
    std::vector<SensorDescription> out(n);
    for (auto& s : out) {
      s.name = r.get_string("name");
      s.kind = r.get_string("kind");
      s.description = r.get_string("description");
      const auto flags = r.get<uint8_t>("flags");
      s.range = flags & 1;
      s.environment = flags & 2;
      if (flags & 4) s.pan_tilt = get_limits(r);
      if (flags & 8) s.zoom = ZoomLimits{r.get<double>("zoom.min_fov_rad"), r.get<double>("zoom.max_fov_rad")};
      const auto np = r.get<uint32_t>("parameter count");
      if (np > r.remaining() / 20) r.fail("parameter count", std::to_string(np) + " is more than the reply can hold");
      s.parameters.resize(np);
      for (auto& p : s.parameters) {
        p.name = r.get_string("parameter.name");
        p.type = r.get_string("parameter.type");
        p.default_value = r.get_string("parameter.default_value");
        p.unit = r.get_string("parameter.unit");
        p.description = r.get_string("parameter.description");
      }
    }
    expect_end(r);
    return out;
  });
}

std::vector<uint8_t> encode_acquisition_header(const AcquisitionHeader& a) {
  ByteWriter w;
  const uint8_t flags = (a.has_range ? 1 : 0) | (a.environment ? 2 : 0) | (a.pan_tilt ? 4 : 0);
  w.put<uint8_t>(flags);
  w.put<uint64_t>(a.range_size);
  if (a.environment) put_environment(w, *a.environment);
  if (a.pan_tilt) {
    w.put<double>(a.pan_tilt->pan_rad);
    w.put<double>(a.pan_tilt->tilt_rad);
  }
  return frame(MessageType::kAcquisition, w);
}

AcquisitionHeader decode_acquisition_header(std::span<const uint8_t> body) {
  return decoding(ErrorCode::kConnection, "acquisition reply", [&] {
    ByteReader r(body, "acquisition reply");
    AcquisitionHeader a;
    const auto flags = r.get<uint8_t>("flags");
    a.has_range = flags & 1;
    a.range_size = r.get<uint64_t>("range_size");
    if (!a.has_range && a.range_size != 0) r.fail("range_size", "nonzero without a range image");
    if (flags & 2) a.environment = get_environment(r);
    if (flags & 4) a.pan_tilt = PanTiltState{r.get<double>("pan_rad"), r.get<double>("tilt_rad")};
    expect_end(r);
    return a;
  });
}

std::vector<uint8_t> encode_pan_tilt(const PanTiltReply& p) {
  ByteWriter w;
  w.put<double>(p.state.pan_rad);
  w.put<double>(p.state.tilt_rad);
  put_limits(w, p.limits);
  return frame(MessageType::kPanTilt, w);
}

PanTiltReply decode_pan_tilt(std::span<const uint8_t> body) {
  return decoding(ErrorCode::kConnection, "pan/tilt reply", [&] {
    ByteReader r(body, "pan/tilt reply");
    PanTiltReply p;
    p.state.pan_rad = r.get<double>("pan_rad");
    p.state.tilt_rad = r.get<double>("tilt_rad");
    p.limits = get_limits(r);
    expect_end(r);
    return p;
  });
}

std::vector<uint8_t> encode_zoom(const ZoomState& z) {
  ByteWriter w;
  w.put<double>(z.fov_rad);
  w.put<double>(z.limits.min_fov_rad);
  w.put<double>(z.limits.max_fov_rad);
  return frame(MessageType::kZoom, w);
}

ZoomState decode_zoom(std::span<const uint8_t> body) {
  return decoding(ErrorCode::kConnection, "zoom reply", [&] {
    ByteReader r(body, "zoom reply");
    ZoomState z;
    z.fov_rad = r.get<double>("fov_rad");
    z.limits.min_fov_rad = r.get<double>("min_fov_rad");
    z.limits.max_fov_rad = r.get<double>("max_fov_rad");
    expect_end(r);
    return z;
  });
}

std::vector<uint8_t> encode_cancelled(uint32_t count) {
  ByteWriter w;
  w.put<uint32_t>(count);
  return frame(MessageType::kCancelled, w);
}

uint32_t decode_cancelled(std::span<const uint8_t> body) {
  return decoding(ErrorCode::kConnection, "cancel reply", [&] {
    ByteReader r(body, "cancel reply");
    const auto n = r.get<uint32_t>("count");
    expect_end(r);
    return n;
  });
}

}  // namespace artisan::sensors::protocol
