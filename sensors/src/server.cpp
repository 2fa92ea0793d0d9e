#include "artisan/sensors/server.hpp"

#include <fcntl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <future>

#include "artisan/core/io/range_image_format.hpp"
#include "artisan/sensors/protocol.hpp"
#include "net.hpp"

namespace artisan::sensors {

namespace pr = protocol;

struct SensorServer::Connection {
  net::Fd fd;
  std::thread thread;
  std::atomic<bool> done{false};
};

namespace {

// Thrown inside serve() to end the connection quietly (peer gone, stop, timeout).
struct Hangup {};

}  // namespace

SensorServer::SensorServer(SensorSet sensors, const ServerConfig& config) : sensors_(std::move(sensors)), config_(config) {
  if (config_.max_clients < 1) throw Error("sensor server: max_clients must be at least 1, not " + std::to_string(config_.max_clients));
  if (config_.chunk_bytes < 1) throw Error("sensor server: chunk_bytes must be at least 1");
  net::Fd listener = net::listen_on({config_.host, config_.port}, 64);
  int p[2];
  if (::pipe2(p, O_CLOEXEC) != 0) throw Error(std::string("sensor server: pipe: ") + std::strerror(errno));
  stop_read_ = p[0];
  stop_write_ = p[1];
  port_ = net::bound_port(listener.get());
  listen_fd_ = listener.release();
  acceptor_ = std::thread(&SensorServer::accept_loop, this);
}

SensorServer::~SensorServer() { stop(); }

ServerStats SensorServer::stats() const {
  std::lock_guard lock(stats_mutex_);
  return stats_;
}

void SensorServer::stop() {
  if (stopped_.exchange(true)) return;
  const char byte = 1;
  while (::write(stop_write_, &byte, 1) < 0 && errno == EINTR) {
  }
  if (acceptor_.joinable()) acceptor_.join();
  reap(true);
  ::close(listen_fd_);
  ::close(stop_read_);
  ::close(stop_write_);
}

void SensorServer::reap(bool all) {
  std::list<std::unique_ptr<Connection>> finished;
  {
    std::lock_guard lock(mutex_);
    for (auto it = connections_.begin(); it != connections_.end();) {
      if (all || (*it)->done) {
        finished.push_back(std::move(*it));
        it = connections_.erase(it);
      } else {
        ++it;
      }
    }
  }
  for (auto& c : finished)
    if (c->thread.joinable()) c->thread.join();
}

void SensorServer::accept_loop() {
  for (;;) {
    const auto st = net::wait_readable(listen_fd_, net::Clock::now() + std::chrono::hours(24), stop_read_);
    if (st == net::IoStatus::kStopped) return;
    if (st != net::IoStatus::kOk) continue;
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC | SOCK_NONBLOCK);
    if (fd < 0) {
      if (errno == EMFILE || errno == ENFILE || errno == ENOBUFS || errno == ENOMEM)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    net::Fd client(fd);
    reap(false);
    int active = 0;
    {
      std::lock_guard lock(stats_mutex_);
      active = stats_.active;
    }
    if (active >= config_.max_clients) {
      const auto frame = pr::encode_error(ErrorCode::kBusy, "sensor server: already serving " + std::to_string(active) +
                                                                " clients (the maximum); try again later");
      net::write_all(client.get(), frame, net::after_seconds(1.0), stop_read_);
      std::lock_guard lock(stats_mutex_);
      ++stats_.errors;
      continue;
    }
    auto c = std::make_unique<Connection>();
    c->fd = std::move(client);
    Connection* raw = c.get();
    {
      std::lock_guard lock(stats_mutex_);
      ++stats_.connections;
      ++stats_.active;
    }
    std::lock_guard lock(mutex_);
    c->thread = std::thread([this, raw] {
      try {
        serve(*raw);
      } catch (...) {
        // serve() handles its own errors; nothing may escape a thread.
      }
      ::shutdown(raw->fd.get(), SHUT_RDWR);
      {
        std::lock_guard stats_lock(stats_mutex_);
        --stats_.active;
      }
      raw->done = true;
    });
    connections_.push_back(std::move(c));
  }
}

void SensorServer::serve(Connection& connection) {
  const int fd = connection.fd.get();
  const auto send = [&](const std::vector<uint8_t>& frame) {
    if (net::write_all(fd, frame, net::after_seconds(config_.io_timeout_s), stop_read_) != net::IoStatus::kOk) throw Hangup{};
  };
  const auto send_error = [&](const SensorError& e) {
    {
      std::lock_guard lock(stats_mutex_);
      ++stats_.errors;
    }
    send(pr::encode_error(e.code(), e.what()));
  };

  std::vector<uint8_t> body;
  for (;;) {
    // Between requests: wait up to the idle timeout; once a frame starts, it must complete in io_timeout.
    if (net::wait_readable(fd, net::after_seconds(config_.idle_timeout_s), stop_read_) != net::IoStatus::kOk) return;
    std::array<uint8_t, pr::kHeaderSize> header_bytes{};
    if (net::read_exact(fd, header_bytes, net::after_seconds(config_.io_timeout_s), stop_read_) != net::IoStatus::kOk) return;
    pr::Request request;
    try {
      const pr::FrameHeader h = pr::decode_header(header_bytes);
      if (h.version != pr::kVersion)
        throw SensorError(ErrorCode::kUnsupportedVersion, "request: protocol version " + std::to_string(h.version) +
                                                              " (this server speaks " + std::to_string(pr::kVersion) + ")");
      if (h.body_size > config_.max_request_bytes)
        throw SensorError(ErrorCode::kRequestTooLarge, "request: body of " + std::to_string(h.body_size) +
                                                           " bytes exceeds the limit of " + std::to_string(config_.max_request_bytes));
      body.resize(h.body_size);
      if (net::read_exact(fd, body, net::after_seconds(config_.io_timeout_s), stop_read_) != net::IoStatus::kOk) return;
      request = pr::decode_request(h.type, body);
    } catch (const SensorError& e) {
      send_error(e);  // the stream cannot be trusted any more: close
      return;
    }
    {
      std::lock_guard lock(stats_mutex_);
      ++stats_.requests;
    }

    try {
      if (std::holds_alternative<pr::ListRequest>(request)) {
        send(pr::encode_sensors(sensors_.describe()));
        continue;
      }
      Sensor& sensor = sensors_.get(pr::sensor_of(request));
      const std::string& name = pr::sensor_of(request);
      if (const auto* get = std::get_if<pr::PanTiltGetRequest>(&request); get || std::holds_alternative<pr::PanTiltMoveRequest>(request)) {
        PanTiltUnit* unit = sensor.pan_tilt();
        if (!unit) throw SensorError(ErrorCode::kNotSupported, "sensor '" + name + "' is not on a pan/tilt unit");
        pr::PanTiltReply reply;
        reply.state = get ? unit->position() : unit->move(std::get<pr::PanTiltMoveRequest>(request).target);
        reply.limits = unit->limits();
        send(pr::encode_pan_tilt(reply));
        continue;
      }
      if (const auto* get = std::get_if<pr::ZoomGetRequest>(&request); get || std::holds_alternative<pr::ZoomSetRequest>(request)) {
        ZoomControl* zoom = sensor.zoom();
        if (!zoom) throw SensorError(ErrorCode::kNotSupported, "sensor '" + name + "' has no zoom");
        pr::ZoomState reply;
        reply.fov_rad = get ? zoom->fov_rad() : zoom->set_fov_rad(std::get<pr::ZoomSetRequest>(request).fov_rad);
        reply.limits = zoom->limits();
        send(pr::encode_zoom(reply));
        continue;
      }
      if (std::holds_alternative<pr::CancelRequest>(request)) {
        send(pr::encode_cancelled(static_cast<uint32_t>(sensor.cancel())));
        continue;
      }
      const auto& acquire = std::get<pr::AcquireMessage>(request);
      const auto deadline = net::after_seconds(config_.acquire_timeout_s);
      const CancelToken token(deadline);
      // The driver works on its own thread; this one watches the client, shutdown and the deadline.
      auto result = std::async(std::launch::async, [&] { return sensor.acquire(acquire.request, token); });
      bool gone = false, stopping = false, late = false;
      while (result.wait_for(std::chrono::milliseconds(10)) != std::future_status::ready) {
        if (net::peer_gone(fd)) gone = true;
        if (stopped_) stopping = true;
        if (net::Clock::now() > deadline + std::chrono::seconds(1)) late = true;  // a driver that ignores its token
        if (gone || stopping || late) {
          token.cancel();
          break;
        }
      }
      if (gone) return;  // the future's destructor waits for the driver
      if (stopping) throw SensorError(ErrorCode::kShuttingDown, "sensor '" + name + "': the server is shutting down");
      if (late) {
        send_error(SensorError(ErrorCode::kTimeout, "sensor '" + name + "': no answer within " +
                                                        std::to_string(config_.acquire_timeout_s) + " s"));
        return;  // closed once the driver lets go (the future's destructor)
      }
      Acquisition acq = result.get();
      pr::AcquisitionHeader h;
      h.environment = acq.environment;
      h.pan_tilt = acq.pan_tilt;
      std::vector<uint8_t> ari;
      if (acq.range) {
        io::RangeImageEncoding enc;
        enc.compress = acquire.compress;
        ari = io::encode_range_image(*acq.range, enc);
        h.has_range = true;
        h.range_size = ari.size();
      }
      send(pr::encode_acquisition_header(h));
      for (size_t at = 0; at < ari.size(); at += config_.chunk_bytes) {
        const size_t n = std::min<size_t>(config_.chunk_bytes, ari.size() - at);
        const auto head = pr::encode_header(pr::MessageType::kData, static_cast<uint32_t>(n));
        const auto io_deadline = net::after_seconds(config_.io_timeout_s);
        if (net::write_all(fd, head, io_deadline, stop_read_) != net::IoStatus::kOk ||
            net::write_all(fd, std::span<const uint8_t>(ari.data() + at, n), io_deadline, stop_read_) != net::IoStatus::kOk)
          throw Hangup{};
      }
      std::lock_guard lock(stats_mutex_);
      ++stats_.acquisitions;
      stats_.payload_bytes += ari.size();
    } catch (const Hangup&) {
      return;
    } catch (const SensorError& e) {
      send_error(e);
      if (e.code() == ErrorCode::kShuttingDown) return;
    } catch (const std::exception& e) {
      send_error(SensorError(ErrorCode::kInternal, std::string("sensor server: ") + e.what()));
    }
  }
}

}  // namespace artisan::sensors
