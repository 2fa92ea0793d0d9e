#pragma once
// The sensor server's client: one TCP connection, one request at a time. Every call throws
// SensorError: the server's code and message, or kConnection (with what broke) when the server
// cannot be reached, stops answering within the timeouts or sends something malformed -- after
// which the client is unusable.
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "artisan/sensors/protocol.hpp"
#include "artisan/sensors/sensor.hpp"

namespace artisan::sensors {

/// The port the server listens on unless told otherwise.
inline constexpr uint16_t kDefaultPort = 7610;

struct ClientConfig {
  double connect_timeout_s = 5.0;        ///< [s]
  double reply_timeout_s = 120.0;        ///< from a request to the first byte of its reply [s]
  double io_timeout_s = 10.0;            ///< to send a request, and for each further frame of a reply [s]
  uint64_t max_payload_bytes = 1ull << 30;  ///< a larger announced acquisition is refused [bytes]
  uint32_t max_frame_bytes = 64u << 20;  ///< a larger reply frame is refused [bytes]
  bool compress = true;                  ///< ask for deflated .ari payloads
};

class SensorClient {
 public:
  /// Connects to "HOST:PORT". Throws SensorError(kConnection) naming the address.
  explicit SensorClient(const std::string& address, const ClientConfig& config = {});
  ~SensorClient();
  SensorClient(SensorClient&&) noexcept;
  SensorClient& operator=(SensorClient&&) noexcept;

  /// The server address to use: `given` when not empty, else $ARTISAN_SENSORD, else 127.0.0.1:7610.
  static std::string resolve_address(const std::string& given);

  const std::string& address() const { return address_; }
  std::vector<SensorDescription> list();
  /// The acquisition as it travelled (.ari bytes unchanged).
  protocol::EncodedAcquisition acquire_encoded(const std::string& sensor, const AcquireRequest& request);
  /// The acquisition decoded (the .ari checksum checked).
  Acquisition acquire(const std::string& sensor, const AcquireRequest& request);
  protocol::PanTiltReply pan_tilt(const std::string& sensor);
  protocol::PanTiltReply move_pan_tilt(const std::string& sensor, const PanTiltState& target);
  protocol::ZoomState zoom(const std::string& sensor);
  protocol::ZoomState set_zoom(const std::string& sensor, double fov_rad);
  /// Cancels the sensor's acquisitions in progress (other clients'); returns how many.
  uint32_t cancel(const std::string& sensor);

 private:
  struct Frame {
    uint16_t type = 0;
    std::vector<uint8_t> body;
  };
  void send(const std::vector<uint8_t>& frame);
  Frame receive(double timeout_s);
  /// Sends the request and returns the reply frame of type `expected`; throws the server's error.
  Frame call(const protocol::Request& request, protocol::MessageType expected);
  [[noreturn]] void broken(const std::string& what);

  std::string address_;
  ClientConfig config_;
  int fd_ = -1;
};

/// "HOST:PORT" split into host and port (an empty HOST means 127.0.0.1). Throws artisan::Error
/// naming the text.
std::pair<std::string, uint16_t> parse_address(const std::string& text);

/// An acquisition decoded: the .ari bytes to a RangeImage (throws SensorError(kConnection) when
/// they are corrupt).
Acquisition decode_acquisition(const protocol::EncodedAcquisition& encoded, const std::string& source);

}  // namespace artisan::sensors
