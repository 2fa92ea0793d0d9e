// artisan-sensord: the sensor server. Serves the simulated workcell's sensors and any folders of
// recordings over TCP (sensors/PROTOCOL.md). Prints the bound address ("HOST:PORT") as one line on
// stdout once it serves; messages go to stderr. Stops cleanly on SIGTERM or SIGINT.
// Exit codes: 0 stopped cleanly, 1 bad input (workcell, folder, address), 2 usage error or internal failure.
#include <pthread.h>
#include <signal.h>

#include <iostream>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include <CLI/CLI.hpp>

#include "artisan/core/error.hpp"
#include "artisan/sensors/client.hpp"
#include "artisan/sensors/drivers.hpp"
#include "artisan/sensors/server.hpp"
#include "artisan/sensors/simulated.hpp"

namespace {

bool is_loopback(const std::string& host) { return host == "localhost" || host.rfind("127.", 0) == 0; }

}  // namespace

int main(int argc, char** argv) {
  using namespace artisan;
  CLI::App app{"artisan-sensord: the sensor server (simulated workcell sensors and file replay over TCP)."};
  app.set_version_flag("--version", "artisan-sensord 0.1.0");
  std::string workcell;
  std::string listen = "127.0.0.1:" + std::to_string(sensors::kDefaultPort);
  std::vector<std::string> replays;
  std::vector<std::string> package_paths;
  sensors::ServerConfig config;
  bool quiet = false;
  app.add_option("--workcell", workcell, "Workcell file (JSON): its sensors are served, driven by one simulator");
  app.add_option("--listen", listen, "HOST:PORT to listen on (IPv4; port 0 = ephemeral)")->capture_default_str();
  app.add_option("--replay", replays, "NAME=FOLDER: a replay sensor serving the recordings in FOLDER (repeatable)");
  app.add_option("--package-path", package_paths, "Folders searched for package:// URIs in the workcell");
  app.add_option("--max-clients", config.max_clients, "Clients served at once")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--max-request-bytes", config.max_request_bytes, "Largest request body accepted [bytes]")->capture_default_str();
  app.add_option("--io-timeout", config.io_timeout_s, "Per-frame I/O timeout [s]")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--acquire-timeout", config.acquire_timeout_s, "Deadline for a driver's answer [s]")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_flag("-q,--quiet", quiet, "No messages on stderr");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }

  // SIGTERM and SIGINT are taken by sigwait() below: block them before any thread starts.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  std::shared_ptr<sensors::SimulatedWorkcell> cell;
  std::unique_ptr<sensors::SensorServer> server;
  try {
    std::tie(config.host, config.port) = sensors::parse_address(listen);
    if (workcell.empty() && replays.empty()) throw Error("nothing to serve: give --workcell FILE and/or --replay NAME=FOLDER");
    const sensors::DriverRegistry registry = sensors::builtin_drivers();
    sensors::SensorSet set;
    if (!workcell.empty()) {
      sim::LoadOptions lo;
      lo.package_paths = {package_paths.begin(), package_paths.end()};
      cell = std::make_shared<sensors::SimulatedWorkcell>(workcell, lo);
      sensors::add_workcell_sensors(set, registry, cell);
    }
    for (const auto& r : replays) {
      const auto eq = r.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == r.size())
        throw Error("--replay '" + r + "': expected NAME=FOLDER");
      sensors::DriverConfig dc;
      dc.name = r.substr(0, eq);
      dc.kind = "replay";
      dc.folder = r.substr(eq + 1);
      set.add(registry.create(dc));
    }
    if (!is_loopback(config.host) && !quiet)
      std::cerr << "artisan-sensord: warning: listening on " << config.host << ", reachable from other machines\n";
    server = std::make_unique<sensors::SensorServer>(std::move(set), config);
    std::cout << server->address() << std::endl;
    if (!quiet) {
      std::cerr << "artisan-sensord: serving on " << server->address() << ":";
      for (const auto& d : server->sensors().describe()) std::cerr << " " << d.name << " (" << d.kind << ")";
      std::cerr << std::endl;
    }
  } catch (const Error& e) {
    std::cerr << "artisan-sensord: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "artisan-sensord: internal error: " << e.what() << "\n";
    return 2;
  }

  int sig = 0;
  while (sigwait(&signals, &sig) != 0) {
  }
  if (!quiet) std::cerr << "artisan-sensord: " << (sig == SIGTERM ? "SIGTERM" : "SIGINT") << ", stopping\n";
  try {
    server->stop();
    const auto s = server->stats();
    server.reset();
    cell.reset();
    if (!quiet)
      std::cerr << "artisan-sensord: stopped after " << s.connections << " connections, " << s.requests << " requests, "
                << s.acquisitions << " acquisitions (" << s.payload_bytes << " bytes), " << s.errors << " error replies\n";
  } catch (const std::exception& e) {
    std::cerr << "artisan-sensord: internal error while stopping: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
