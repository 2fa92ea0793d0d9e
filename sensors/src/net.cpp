#include "net.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>

#include "artisan/core/error.hpp"
#include "artisan/sensors/sensor.hpp"

namespace artisan::sensors::net {

Fd& Fd::operator=(Fd&& o) noexcept {
  if (this != &o) {
    reset();
    fd_ = std::exchange(o.fd_, -1);
  }
  return *this;
}

void Fd::reset() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

HostPort parse_host_port(const std::string& text) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos) throw Error("address '" + text + "': expected HOST:PORT, e.g. 127.0.0.1:7610");
  HostPort hp;
  hp.host = text.substr(0, colon);
  if (hp.host.empty()) hp.host = "127.0.0.1";
  const std::string port = text.substr(colon + 1);
  unsigned v = 0;
  const auto [p, ec] = std::from_chars(port.data(), port.data() + port.size(), v);
  if (port.empty() || ec != std::errc() || p != port.data() + port.size() || v > 65535)
    throw Error("address '" + text + "': port '" + port + "' is not a number from 0 to 65535");
  hp.port = static_cast<uint16_t>(v);
  return hp;
}

namespace {

int remaining_ms(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  if (left <= 0) return 0;
  return left > 1000 ? 1000 : static_cast<int>(left) + 1;
}

// Waits for `events` on fd; kOk when they (or a hang-up) came.
IoStatus wait_for(int fd, short events, Clock::time_point deadline, int stop_fd) {
  for (;;) {
    pollfd p[2] = {{fd, events, 0}, {stop_fd, POLLIN, 0}};
    const int n = ::poll(p, stop_fd >= 0 ? 2 : 1, remaining_ms(deadline));
    if (n < 0) {
      if (errno == EINTR) continue;
      return IoStatus::kError;
    }
    if (stop_fd >= 0 && (p[1].revents & POLLIN)) return IoStatus::kStopped;
    if (p[0].revents) return IoStatus::kOk;
    if (Clock::now() >= deadline) return IoStatus::kTimeout;
  }
}

}  // namespace

IoStatus wait_readable(int fd, Clock::time_point deadline, int stop_fd) { return wait_for(fd, POLLIN, deadline, stop_fd); }

IoStatus read_exact(int fd, std::span<uint8_t> bytes, Clock::time_point deadline, int stop_fd) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::recv(fd, bytes.data() + done, bytes.size() - done, MSG_DONTWAIT);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    if (n == 0) return IoStatus::kClosed;
    if (errno == EINTR) continue;
    if (errno != EAGAIN && errno != EWOULDBLOCK) return IoStatus::kError;
    const IoStatus s = wait_for(fd, POLLIN, deadline, stop_fd);
    if (s != IoStatus::kOk) return s;
  }
  return IoStatus::kOk;
}

IoStatus write_all(int fd, std::span<const uint8_t> bytes, Clock::time_point deadline, int stop_fd) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) return IoStatus::kError;
    const IoStatus s = wait_for(fd, POLLOUT, deadline, stop_fd);
    if (s != IoStatus::kOk) return s;
  }
  return IoStatus::kOk;
}

bool peer_gone(int fd) {
  pollfd p{fd, static_cast<short>(POLLIN | POLLRDHUP), 0};
  if (::poll(&p, 1, 0) <= 0) return false;
  if (p.revents & (POLLHUP | POLLERR | POLLRDHUP)) return true;
  if (p.revents & POLLIN) {
    uint8_t b;
    const ssize_t n = ::recv(fd, &b, 1, MSG_PEEK | MSG_DONTWAIT);
    return n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR);
  }
  return false;
}

Fd connect_to(const HostPort& address, Clock::time_point deadline) {
  const std::string name = address.host + ":" + std::to_string(address.port);
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  const std::string port = std::to_string(address.port);
  if (const int rc = ::getaddrinfo(address.host.c_str(), port.c_str(), &hints, &found); rc != 0)
    throw SensorError(ErrorCode::kConnection, "sensor server " + name + ": " + ::gai_strerror(rc));
  std::string why = "no address";
  for (addrinfo* a = found; a; a = a->ai_next) {
    Fd fd(::socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC | SOCK_NONBLOCK, a->ai_protocol));
    if (!fd) continue;
    int rc = ::connect(fd.get(), a->ai_addr, a->ai_addrlen);
    if (rc < 0 && errno == EINPROGRESS) {
      if (wait_for(fd.get(), POLLOUT, deadline, -1) != IoStatus::kOk) {
        why = "connection timed out";
        continue;
      }
      int err = 0;
      socklen_t len = sizeof err;
      ::getsockopt(fd.get(), SOL_SOCKET, SO_ERROR, &err, &len);
      if (err != 0) {
        errno = err;
        rc = -1;
      } else {
        rc = 0;
      }
    }
    if (rc < 0) {
      why = std::strerror(errno);
      continue;
    }
    const int one = 1;
    ::setsockopt(fd.get(), IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    ::freeaddrinfo(found);
    return fd;
  }
  ::freeaddrinfo(found);
  throw SensorError(ErrorCode::kConnection, "sensor server " + name + ": cannot connect: " + why);
}

Fd listen_on(const HostPort& address, int backlog) {
  const std::string name = address.host + ":" + std::to_string(address.port);
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(address.port);
  const std::string host = address.host == "localhost" ? "127.0.0.1" : address.host;
  if (::inet_pton(AF_INET, host.c_str(), &sa.sin_addr) != 1)
    throw Error("listen address '" + name + "': '" + address.host + "' is not an IPv4 address");
  Fd fd(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
  if (!fd) throw Error("listen address '" + name + "': socket: " + std::strerror(errno));
  const int one = 1;
  ::setsockopt(fd.get(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(fd.get(), reinterpret_cast<sockaddr*>(&sa), sizeof sa) < 0)
    throw Error("listen address '" + name + "': cannot bind: " + std::strerror(errno));
  if (::listen(fd.get(), backlog) < 0) throw Error("listen address '" + name + "': cannot listen: " + std::strerror(errno));
  return fd;
}

uint16_t bound_port(int fd) {
  sockaddr_in sa{};
  socklen_t len = sizeof sa;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len);
  return ntohs(sa.sin_port);
}

}  // namespace artisan::sensors::net
