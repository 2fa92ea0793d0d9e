#pragma once
// The sensor server: serves a SensorSet over TCP with the protocol of PROTOCOL.md. One thread
// per connection (up to max_clients); each acquisition runs on its own thread while the
// connection watches the client, the deadline and shutdown.
#include <atomic>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "artisan/sensors/drivers.hpp"

namespace artisan::sensors {

struct ServerConfig {
  std::string host = "127.0.0.1";       ///< IPv4 address to listen on (loopback unless asked otherwise)
  uint16_t port = 7610;                 ///< TCP port; 0 = an ephemeral one (see SensorServer::port())
  int max_clients = 16;                 ///< connections beyond this get a kBusy error and are closed
  uint32_t max_request_bytes = 65536;   ///< a request body larger than this is refused, connection closed [bytes]
  uint32_t chunk_bytes = 1u << 20;      ///< acquisition payloads travel in DATA frames of at most this [bytes]
  double io_timeout_s = 10.0;           ///< a started request must complete, and each reply frame be taken, within this [s]
  double idle_timeout_s = 600.0;        ///< a connection without a request for this long is closed [s]
  double acquire_timeout_s = 60.0;      ///< a driver that has not answered by then: kTimeout error reply [s]
};

/// Counters, for tests and logs.
struct ServerStats {
  uint64_t connections = 0;    ///< accepted
  uint64_t requests = 0;       ///< decoded
  uint64_t errors = 0;         ///< error replies sent
  uint64_t acquisitions = 0;   ///< acquisitions sent whole
  uint64_t payload_bytes = 0;  ///< acquisition payload bytes sent
  int active = 0;              ///< connections open now
};

class SensorServer {
 public:
  /// Binds, listens and starts serving. Throws artisan::Error naming the address when it cannot.
  SensorServer(SensorSet sensors, const ServerConfig& config = {});
  /// stop()
  ~SensorServer();
  SensorServer(const SensorServer&) = delete;
  SensorServer& operator=(const SensorServer&) = delete;

  /// The bound port (the ephemeral one when config.port was 0).
  uint16_t port() const { return port_; }
  /// "HOST:PORT" as bound.
  std::string address() const { return config_.host + ":" + std::to_string(port_); }
  const SensorSet& sensors() const { return sensors_; }
  ServerStats stats() const;

  /// Stops accepting; connections finish the frame they are sending, acquisitions in progress
  /// are cancelled (their clients get kShuttingDown), every thread is joined. Idempotent.
  void stop();

 private:
  struct Connection;
  void accept_loop();
  void serve(Connection& connection);
  void reap(bool all);

  SensorSet sensors_;
  ServerConfig config_;
  int listen_fd_ = -1;
  int stop_read_ = -1, stop_write_ = -1;  ///< a pipe: readable once stop() was called
  uint16_t port_ = 0;
  std::atomic<bool> stopped_{false};
  std::thread acceptor_;
  std::mutex mutex_;
  std::list<std::unique_ptr<Connection>> connections_;
  mutable std::mutex stats_mutex_;
  ServerStats stats_;
};

}  // namespace artisan::sensors
