// Sensor server throughput over 127.0.0.1: acquisitions per second and payload MB/s with 1 and 4
// concurrent clients, for Vivid-sized (200 x 200 range + 400 x 400 colour) and 640 x 480
// (Pioneer: range + three 640 x 480 cameras) acquisitions. Transport is separated from simulation:
// "memory" serves a recorded simulator acquisition held in memory (encode + socket + client
// decode: the transport alone), "replay" serves it from its .ari file through the replay driver
// (adds reading and inflating the file), "simulated" runs the simulator per request (one simulator, so
// concurrent clients queue), and "direct" is the simulator alone with no server. Payloads are
// measured both deflated (the default) and raw. JSON on stdout.
#include <algorithm>
#include <chrono>
#include <iostream>
#include <thread>

#include <nlohmann/json.hpp>

#include "artisan/core/io/range_image_format.hpp"
#include "artisan/sensors/client.hpp"
#include "artisan/sensors/server.hpp"
#include "artisan/sensors/simulated.hpp"
#include "test_support.hpp"

namespace {

using namespace artisan;
using nlohmann::json;

/// Serves one acquisition held in memory: the transport alone (encode, socket, client decode).
class MemorySensor : public sensors::Sensor {
 public:
  MemorySensor(const std::string& name, std::filesystem::path file) : range_(io::read_range_image(file)) {
    description_.name = name;
    description_.kind = "memory";
    description_.range = true;
  }
  sensors::SensorDescription describe() const override { return description_; }

 protected:
  sensors::Acquisition do_acquire(const sensors::AcquireRequest&, const sensors::CancelToken&) override {
    sensors::Acquisition a;
    a.range = range_;
    return a;
  }

 private:
  sensors::SensorDescription description_;
  RangeImage range_;
};

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// `clients` threads, each with its own connection, take `per_client` acquisitions.
json run_case(const std::string& address, const std::string& sensor, const sensors::AcquireRequest& request, int clients,
              int per_client, bool compress) {
  std::vector<std::thread> threads;
  std::vector<size_t> bytes(clients, 0);
  std::vector<std::vector<double>> latency(clients);
  // Connect (and warm up once) before the clock starts.
  std::vector<sensors::SensorClient> conns;
  sensors::ClientConfig cc;
  cc.compress = compress;
  for (int c = 0; c < clients; ++c) conns.emplace_back(address, cc);
  conns[0].acquire(sensor, request);
  const auto t0 = std::chrono::steady_clock::now();
  for (int c = 0; c < clients; ++c)
    threads.emplace_back([&, c] {
      for (int i = 0; i < per_client; ++i) {
        const auto t = std::chrono::steady_clock::now();
        const auto a = conns[c].acquire_encoded(sensor, request);
        (void)sensors::decode_acquisition(a, sensor);  // what a client does with it
        latency[c].push_back(seconds_since(t));
        bytes[c] += a.range_ari.size();
      }
    });
  for (auto& t : threads) t.join();
  const double s = seconds_since(t0);
  size_t total = 0;
  std::vector<double> all;
  for (int c = 0; c < clients; ++c) {
    total += bytes[c];
    all.insert(all.end(), latency[c].begin(), latency[c].end());
  }
  std::sort(all.begin(), all.end());
  const int n = clients * per_client;
  return {{"clients", clients},
          {"acquisitions", n},
          {"compressed", compress},
          {"payload_bytes_each", total / n},
          {"acquisitions_per_s", n / s},
          {"MB_per_s", total / s / 1e6},
          {"latency_median_ms", 1e3 * all[all.size() / 2]}};
}

}  // namespace

int main() {
  const std::filesystem::path cell_file = std::string(ARTISAN_DATA_DIR) + "/workcells/pipework.json";
  artisan::test::TempDir dir;

  // Record one acquisition of each simulated range sensor (direct driver calls) for replay, and
  // time the simulator alone.
  json direct = json::object();
  {
    auto cell = std::make_shared<sensors::SimulatedWorkcell>(cell_file);
    for (const auto& [name, file, n] : {std::tuple{"vivid", "vivid_sized.ari", 5}, std::tuple{"pioneer", "pioneer_640x480.ari", 3}}) {
      sensors::SimulatedRangeSensor s(cell, name);
      const auto a = s.acquire({});
      io::write_range_image(*a.range, dir / file);
      const auto t0 = std::chrono::steady_clock::now();
      for (int i = 0; i < n; ++i) s.acquire({});
      const double per = seconds_since(t0) / n;
      const auto e0 = std::chrono::steady_clock::now();
      const auto deflated = io::encode_range_image(*a.range);
      const double encode_s = seconds_since(e0);
      const auto r0 = std::chrono::steady_clock::now();
      const auto raw = io::encode_range_image(*a.range, {false});
      const double encode_raw_s = seconds_since(r0);
      direct[name] = {{"acquisitions_per_s", 1.0 / per},
                      {"width", a.range->width},
                      {"height", a.range->height},
                      {"camera_images", a.range->images.size()},
                      {"ari_bytes_deflated", deflated.size()},
                      {"ari_bytes_raw", raw.size()},
                      {"encode_deflated_ms", 1e3 * encode_s},
                      {"encode_raw_ms", 1e3 * encode_raw_s}};
    }
  }

  sensors::SensorSet set;
  auto cell = std::make_shared<sensors::SimulatedWorkcell>(cell_file);
  sensors::add_workcell_sensors(set, sensors::builtin_drivers(), cell);
  set.add(sensors::builtin_drivers().create({"files", "replay", nullptr, dir.path()}));
  set.add(std::make_unique<MemorySensor>("memory_vivid_sized", dir / "vivid_sized.ari"));
  set.add(std::make_unique<MemorySensor>("memory_pioneer_640x480", dir / "pioneer_640x480.ari"));
  sensors::ServerConfig config;
  config.port = 0;
  sensors::SensorServer server(std::move(set), config);
  const std::string address = server.address();

  json memory = json::array(), replay = json::array(), simulated = json::array();
  for (const auto& [label, file, per_client] : {std::tuple{"vivid_200x200", "vivid_sized", 60}, std::tuple{"640x480", "pioneer_640x480", 16}})
    for (int clients : {1, 4}) {
      for (bool compress : {false, true}) {
        json j = run_case(address, std::string("memory_") + file, {}, clients, clients == 1 ? per_client : per_client / 2, compress);
        j["size"] = label;
        memory.push_back(j);
      }
      sensors::AcquireRequest r;
      r.params["file"] = file;
      json j = run_case(address, "files", r, clients, clients == 1 ? per_client : per_client / 2, false);
      j["size"] = label;
      replay.push_back(j);
    }
  for (const auto& [label, sensor, per_client] : {std::tuple{"vivid_200x200", "vivid", 6}, std::tuple{"640x480", "pioneer", 4}})
    for (int clients : {1, 4}) {
      json j = run_case(address, sensor, {}, clients, clients == 1 ? per_client : per_client / 2, true);
      j["size"] = label;
      j["sensor"] = sensor;
      simulated.push_back(j);
    }
  json out = {{"benchmark", "sensors"},
              {"transport", "TCP over 127.0.0.1, one connection per client"},
              {"direct_simulator", direct},
              {"memory", memory},
              {"replay", replay},
              {"simulated", simulated}};
  std::cout << out.dump(2) << "\n";
  return 0;
}
