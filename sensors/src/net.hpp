#pragma once
// POSIX TCP helpers shared by the server and the client (internal): an owning descriptor,
// address parsing, and reads/writes with deadlines that a stop descriptor can interrupt.
#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <utility>

namespace artisan::sensors::net {

using Clock = std::chrono::steady_clock;

/// Owns a file descriptor; closes it once.
class Fd {
 public:
  Fd() = default;
  explicit Fd(int fd) : fd_(fd) {}
  Fd(Fd&& o) noexcept : fd_(std::exchange(o.fd_, -1)) {}
  Fd& operator=(Fd&& o) noexcept;
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  ~Fd() { reset(); }
  int get() const { return fd_; }
  explicit operator bool() const { return fd_ >= 0; }
  void reset();
  /// Gives up ownership.
  int release() { return std::exchange(fd_, -1); }

 private:
  int fd_ = -1;
};

struct HostPort {
  std::string host;
  uint16_t port = 0;
};

/// "HOST:PORT" (HOST may be empty: 127.0.0.1). Throws artisan::Error naming the text.
HostPort parse_host_port(const std::string& text);

/// Why an I/O call returned without finishing.
enum class IoStatus { kOk, kClosed, kTimeout, kStopped, kError };

/// Waits until `fd` is readable (or hung up), the deadline passes, or `stop_fd` (>= 0) is readable.
IoStatus wait_readable(int fd, Clock::time_point deadline, int stop_fd = -1);
/// Reads exactly `bytes.size()` bytes. kClosed when the peer closed before all arrived.
IoStatus read_exact(int fd, std::span<uint8_t> bytes, Clock::time_point deadline, int stop_fd = -1);
/// Writes every byte (MSG_NOSIGNAL: a dead peer gives kError, never SIGPIPE).
IoStatus write_all(int fd, std::span<const uint8_t> bytes, Clock::time_point deadline, int stop_fd = -1);
/// True when the peer has closed or reset the connection (without consuming data).
bool peer_gone(int fd);

/// A connected TCP socket (TCP_NODELAY); throws SensorError(kConnection) naming the address.
Fd connect_to(const HostPort& address, Clock::time_point deadline);
/// A listening socket bound to an IPv4 address; throws artisan::Error naming the address.
Fd listen_on(const HostPort& address, int backlog);
/// The port a socket is bound to.
uint16_t bound_port(int fd);

inline Clock::time_point after_seconds(double s) {
  return Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

}  // namespace artisan::sensors::net
