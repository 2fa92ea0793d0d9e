#pragma once
// Helpers for the sensor-server tests and benchmark: a test driver that fails on demand, a
// synthetic range image of any size, and a raw protocol connection that can misbehave.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <random>
#include <stdexcept>
#include <thread>

#include "artisan/sensors/drivers.hpp"
#include "artisan/sensors/protocol.hpp"

namespace artisan::sensors::test {

/// A range image of the given size with `cameras` RGB images of the same size: a tilted plane
/// with pseudo-random dropouts and texture (deterministic for a seed).
inline RangeImage synthetic_range_image(int width, int height, int cameras, uint32_t seed, int camera_width = 0, int camera_height = 0) {
  RangeImage r = RangeImage::empty_of_size(width, height);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> noise(-0.001f, 0.001f);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const size_t i = r.index(x, y);
      if (rng() % 20 == 0) continue;
      const float z = 1.0f + 0.0005f * static_cast<float>(x) + noise(rng);
      r.points_sensor[i] = {(static_cast<float>(x) - width / 2.0f) * z / 500.0f, (static_cast<float>(y) - height / 2.0f) * z / 500.0f, z};
      r.valid[i] = 1;
    }
  const int cw = camera_width > 0 ? camera_width : width, ch = camera_height > 0 ? camera_height : height;
  for (int c = 0; c < cameras; ++c) {
    CameraImage cam;
    cam.name = c == 0 ? "left" : c == 1 ? "right" : "top";
    cam.image.width = cw;
    cam.image.height = ch;
    cam.image.pixels.resize(static_cast<size_t>(cw) * ch * 3);
    for (size_t i = 0; i < cam.image.pixels.size(); ++i) cam.image.pixels[i] = static_cast<uint8_t>((i * 7 + (rng() & 15)) & 0xff);
    r.images.push_back(std::move(cam));
  }
  r.sensor.kind = "synthetic";
  r.sensor.name = "synthetic";
  r.sensor.timestamp_s = 1000.0 + seed;
  return r;
}

/// A test driver: parameter "mode" = "ok" (a small image), "throw" (a hardware fault), "slow"
/// (waits, honouring its token, until cancelled or past the deadline), "stubborn" (ignores its
/// token for `stubborn_s`). Has a zoom, to exercise that capability.
class FaultySensor : public Sensor, private ZoomControl {
 public:
  explicit FaultySensor(const std::string& name) {
    description_.name = name;
    description_.kind = "test-faulty";
    description_.description = "fails on demand";
    description_.range = true;
    description_.zoom = ZoomLimits{0.2, 0.9};
    description_.parameters = {{"mode", "string", "ok", "", "ok, throw, slow or stubborn"}};
  }
  SensorDescription describe() const override { return description_; }
  ZoomControl* zoom() override { return this; }
  double stubborn_s = 2.0;

 protected:
  Acquisition do_acquire(const AcquireRequest& request, const CancelToken& cancel) override {
    const std::string mode = parameter_text(description_, request.params, "mode");
    if (mode == "throw") throw std::runtime_error("simulated hardware fault: laser interlock open");
    if (mode == "slow")
      for (;;) {
        cancel.check("sensor '" + description_.name + "'");
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
    if (mode == "stubborn") std::this_thread::sleep_for(std::chrono::duration<double>(stubborn_s));
    Acquisition a;
    a.range = synthetic_range_image(8, 6, 1, 3);
    return a;
  }

 private:
  ZoomLimits limits() const override { return *description_.zoom; }
  double fov_rad() const override { return fov_; }
  double set_fov_rad(double fov) override {
    if (fov < description_.zoom->min_fov_rad || fov > description_.zoom->max_fov_rad)
      throw SensorError(ErrorCode::kOutOfLimits, "zoom " + std::to_string(fov) + " rad is beyond the limits");
    return fov_ = fov;
  }
  SensorDescription description_;
  double fov_ = 0.5;
};

/// A protocol connection without the client library's manners: sends anything, reads frames,
/// can vanish with a reset.
class RawConnection {
 public:
  explicit RawConnection(uint16_t port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_port = htons(port);
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&sa), sizeof sa) != 0) throw std::runtime_error("connect failed");
  }
  ~RawConnection() { close(); }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  /// Closes with a TCP reset (as when a process is killed with data unread).
  void reset() {
    linger l{1, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_LINGER, &l, sizeof l);
    close();
  }
  void send(const std::vector<uint8_t>& bytes) {
    size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::send(fd_, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
      if (n <= 0) throw std::runtime_error("send failed");
      done += static_cast<size_t>(n);
    }
  }
  /// Reads exactly n bytes; false on EOF or after `timeout_s`.
  bool read(uint8_t* out, size_t n, double timeout_s = 10.0) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    size_t done = 0;
    while (done < n) {
      pollfd p{fd_, POLLIN, 0};
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
      if (left <= 0 || ::poll(&p, 1, static_cast<int>(left)) <= 0) return false;
      const ssize_t got = ::recv(fd_, out + done, n - done, 0);
      if (got <= 0) return false;
      done += static_cast<size_t>(got);
    }
    return true;
  }
  struct Frame {
    uint16_t type = 0;
    std::vector<uint8_t> body;
  };
  /// The next frame, or none on EOF/timeout.
  std::optional<Frame> frame(double timeout_s = 10.0) {
    std::array<uint8_t, protocol::kHeaderSize> h{};
    if (!read(h.data(), h.size(), timeout_s)) return std::nullopt;
    const auto header = protocol::decode_header(h);
    Frame f;
    f.type = header.type;
    f.body.resize(header.body_size);
    if (!read(f.body.data(), f.body.size(), timeout_s)) return std::nullopt;
    return f;
  }
  /// True when the server has closed the connection (EOF within `timeout_s`).
  bool closed_by_peer(double timeout_s = 5.0) {
    uint8_t b;
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout_s * 1000)) <= 0) return false;
    return ::recv(fd_, &b, 1, 0) <= 0;
  }
  int fd() const { return fd_; }

 private:
  int fd_ = -1;
};

}  // namespace artisan::sensors::test
