#include "artisan/sensors/client.hpp"

#include <unistd.h>

#include <cstdlib>

#include "artisan/core/io/range_image_format.hpp"
#include "net.hpp"

namespace artisan::sensors {

namespace pr = protocol;

std::pair<std::string, uint16_t> parse_address(const std::string& text) {
  const net::HostPort hp = net::parse_host_port(text);
  return {hp.host, hp.port};
}

std::string SensorClient::resolve_address(const std::string& given) {
  if (!given.empty()) return given;
  if (const char* env = std::getenv("ARTISAN_SENSORD"); env && *env) return env;
  return "127.0.0.1:" + std::to_string(kDefaultPort);
}

SensorClient::SensorClient(const std::string& address, const ClientConfig& config) : address_(address), config_(config) {
  net::HostPort hp;
  try {
    hp = net::parse_host_port(address);
  } catch (const SensorError&) {
    throw;
  } catch (const Error& e) {
    throw SensorError(ErrorCode::kConnection, e.what());
  }
  fd_ = net::connect_to(hp, net::after_seconds(config_.connect_timeout_s)).release();
}

SensorClient::~SensorClient() {
  if (fd_ >= 0) ::close(fd_);
}

SensorClient::SensorClient(SensorClient&& o) noexcept : address_(std::move(o.address_)), config_(o.config_), fd_(std::exchange(o.fd_, -1)) {}

SensorClient& SensorClient::operator=(SensorClient&& o) noexcept {
  if (this != &o) {
    if (fd_ >= 0) ::close(fd_);
    address_ = std::move(o.address_);
    config_ = o.config_;
    fd_ = std::exchange(o.fd_, -1);
  }
  return *this;
}

void SensorClient::broken(const std::string& what) {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  throw SensorError(ErrorCode::kConnection, "sensor server " + address_ + ": " + what);
}

namespace {

const char* status_text(net::IoStatus s) {
  switch (s) {
    case net::IoStatus::kClosed: return "the server closed the connection";
    case net::IoStatus::kTimeout: return "no answer within the timeout";
    case net::IoStatus::kError: return "connection broken";
    default: return "interrupted";
  }
}

}  // namespace

void SensorClient::send(const std::vector<uint8_t>& frame) {
  if (fd_ < 0) broken("the connection is closed after an earlier failure");
  const auto s = net::write_all(fd_, frame, net::after_seconds(config_.io_timeout_s));
  if (s != net::IoStatus::kOk) broken(std::string("sending a request: ") + status_text(s));
}

SensorClient::Frame SensorClient::receive(double timeout_s) {
  if (fd_ < 0) broken("the connection is closed after an earlier failure");
  std::array<uint8_t, pr::kHeaderSize> head{};
  auto s = net::wait_readable(fd_, net::after_seconds(timeout_s));
  if (s == net::IoStatus::kOk) s = net::read_exact(fd_, head, net::after_seconds(config_.io_timeout_s));
  if (s != net::IoStatus::kOk) broken(std::string("waiting for a reply: ") + status_text(s));
  pr::FrameHeader h;
  try {
    h = pr::decode_header(head);
  } catch (const SensorError& e) {
    broken(std::string("reply: ") + e.what());
  }
  if (h.version != pr::kVersion) broken("reply in protocol version " + std::to_string(h.version) + ", expected " + std::to_string(pr::kVersion));
  if (h.body_size > config_.max_frame_bytes)
    broken("reply frame of " + std::to_string(h.body_size) + " bytes exceeds the limit of " + std::to_string(config_.max_frame_bytes));
  Frame f;
  f.type = h.type;
  f.body.resize(h.body_size);
  s = net::read_exact(fd_, f.body, net::after_seconds(config_.io_timeout_s));
  if (s != net::IoStatus::kOk) broken(std::string("reading a reply: ") + status_text(s));
  return f;
}

SensorClient::Frame SensorClient::call(const pr::Request& request, pr::MessageType expected) {
  send(pr::encode_request(request));
  Frame f = receive(config_.reply_timeout_s);
  if (f.type == static_cast<uint16_t>(pr::MessageType::kError)) {
    SensorError e = [&] {
      try {
        return pr::decode_error(f.body);
      } catch (const SensorError& bad) {
        broken(bad.what());
      }
    }();
    // Errors after which the server closes the connection.
    const auto c = e.code();
    if (c == ErrorCode::kMalformedRequest || c == ErrorCode::kRequestTooLarge || c == ErrorCode::kUnsupportedVersion ||
        c == ErrorCode::kBusy || c == ErrorCode::kShuttingDown) {
      ::close(fd_);
      fd_ = -1;
    }
    throw e;
  }
  if (f.type != static_cast<uint16_t>(expected))
    broken("reply of message type " + std::to_string(f.type) + ", expected " + std::to_string(static_cast<int>(expected)));
  return f;
}

std::vector<SensorDescription> SensorClient::list() {
  const Frame f = call(pr::ListRequest{}, pr::MessageType::kSensors);
  try {
    return pr::decode_sensors(f.body);
  } catch (const SensorError& e) {
    broken(e.what());
  }
}

pr::EncodedAcquisition SensorClient::acquire_encoded(const std::string& sensor, const AcquireRequest& request) {
  pr::AcquireMessage m;
  m.sensor = sensor;
  m.request = request;
  m.compress = config_.compress;
  const Frame f = call(m, pr::MessageType::kAcquisition);
  pr::AcquisitionHeader h;
  try {
    h = pr::decode_acquisition_header(f.body);
  } catch (const SensorError& e) {
    broken(e.what());
  }
  if (h.range_size > config_.max_payload_bytes)
    broken("acquisition of " + std::to_string(h.range_size) + " bytes exceeds the limit of " + std::to_string(config_.max_payload_bytes));
  pr::EncodedAcquisition out;
  out.has_range = h.has_range;
  out.environment = h.environment;
  out.pan_tilt = h.pan_tilt;
  // DATA frames are read straight into place: one allocation, no copy.
  out.range_ari.resize(h.range_size);
  size_t at = 0;
  while (at < h.range_size) {
    std::array<uint8_t, pr::kHeaderSize> head{};
    auto s = net::read_exact(fd_, head, net::after_seconds(config_.io_timeout_s));
    if (s != net::IoStatus::kOk) broken(std::string("reading the acquisition: ") + status_text(s));
    pr::FrameHeader dh;
    try {
      dh = pr::decode_header(head);
    } catch (const SensorError& e) {
      broken(std::string("acquisition data: ") + e.what());
    }
    if (dh.version != pr::kVersion || dh.type != static_cast<uint16_t>(pr::MessageType::kData))
      broken("expected a data frame of the acquisition, got message type " + std::to_string(dh.type));
    if (dh.body_size == 0 || dh.body_size > h.range_size - at || dh.body_size > config_.max_frame_bytes)
      broken("data frame of " + std::to_string(dh.body_size) + " bytes does not fit the announced " + std::to_string(h.range_size));
    s = net::read_exact(fd_, std::span<uint8_t>(out.range_ari.data() + at, dh.body_size), net::after_seconds(config_.io_timeout_s));
    if (s != net::IoStatus::kOk) broken(std::string("reading the acquisition: ") + status_text(s));
    at += dh.body_size;
  }
  return out;
}

Acquisition decode_acquisition(const pr::EncodedAcquisition& encoded, const std::string& source) {
  Acquisition out;
  out.environment = encoded.environment;
  out.pan_tilt = encoded.pan_tilt;
  if (encoded.has_range) {
    try {
      out.range = io::decode_range_image(encoded.range_ari, source);
    } catch (const Error& e) {
      throw SensorError(ErrorCode::kConnection, e.what());
    }
  }
  return out;
}

Acquisition SensorClient::acquire(const std::string& sensor, const AcquireRequest& request) {
  return decode_acquisition(acquire_encoded(sensor, request), "sensor '" + sensor + "' via " + address_);
}

pr::PanTiltReply SensorClient::pan_tilt(const std::string& sensor) {
  const Frame f = call(pr::PanTiltGetRequest{sensor}, pr::MessageType::kPanTilt);
  try {
    return pr::decode_pan_tilt(f.body);
  } catch (const SensorError& e) {
    broken(e.what());
  }
}

pr::PanTiltReply SensorClient::move_pan_tilt(const std::string& sensor, const PanTiltState& target) {
  const Frame f = call(pr::PanTiltMoveRequest{sensor, target}, pr::MessageType::kPanTilt);
  try {
    return pr::decode_pan_tilt(f.body);
  } catch (const SensorError& e) {
    broken(e.what());
  }
}

pr::ZoomState SensorClient::zoom(const std::string& sensor) {
  const Frame f = call(pr::ZoomGetRequest{sensor}, pr::MessageType::kZoom);
  try {
    return pr::decode_zoom(f.body);
  } catch (const SensorError& e) {
    broken(e.what());
  }
}

pr::ZoomState SensorClient::set_zoom(const std::string& sensor, double fov_rad) {
  const Frame f = call(pr::ZoomSetRequest{sensor, fov_rad}, pr::MessageType::kZoom);
  try {
    return pr::decode_zoom(f.body);
  } catch (const SensorError& e) {
    broken(e.what());
  }
}

uint32_t SensorClient::cancel(const std::string& sensor) {
  const Frame f = call(pr::CancelRequest{sensor}, pr::MessageType::kCancelled);
  try {
    return pr::decode_cancelled(f.body);
  } catch (const SensorError& e) {
    broken(e.what());
  }
}

}  // namespace artisan::sensors
