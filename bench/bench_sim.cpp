// Simulated workcell throughput: scene load (+ physics settling) time, 640 x 480 depth + colour
// frames per second, depth-only frames per second, and full acquisitions per second for the
// Vivid 700 and the Pioneer (stereo included; ground truth included, which renders every
// instance alone for the visible fractions). JSON on stdout.
#include <chrono>
#include <iostream>

#include <nlohmann/json.hpp>

#include "artisan/sim/simulator.hpp"

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  using namespace artisan;
  const std::string path = argc > 1 ? argv[1] : std::string(ARTISAN_DATA_DIR) + "/workcells/pipework.json";
  auto t0 = std::chrono::steady_clock::now();
  auto cell = sim::load_workcell(path);
  const double load_s = seconds_since(t0);
  size_t triangles = 0;
  for (const auto& b : cell.bodies) triangles += b.mesh.faces.size();
  t0 = std::chrono::steady_clock::now();
  sim::Simulator simulator(std::move(cell));
  const double settle_and_upload_s = seconds_since(t0);

  const auto cam = sim::camera_from_fov(640, 480, 1.0);
  const Transform T_world_camera = simulator.workcell().T_world_sensor(simulator.workcell().sensor("vivid"));
  auto rate = [&](const sim::RenderOptions& o, int frames) {
    simulator.render(cam, T_world_camera, o);  // warm up
    const auto t = std::chrono::steady_clock::now();
    for (int i = 0; i < frames; ++i) simulator.render(cam, T_world_camera, o);
    return frames / seconds_since(t);
  };
  sim::RenderOptions depth_colour;
  depth_colour.instances = false;
  sim::RenderOptions depth_only;
  depth_only.instances = false;
  depth_only.color = false;
  sim::RenderOptions all;
  auto scans = [&](const std::string& sensor, int n) {
    sim::ScanRequest req;
    req.sensor = sensor;
    simulator.scan(req);
    const auto t = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) {
      req.seed = static_cast<uint64_t>(i);
      simulator.scan(req);
    }
    return n / seconds_since(t);
  };
  nlohmann::json j = {{"benchmark", "sim"},
                      {"workcell", path},
                      {"bodies", simulator.workcell().bodies.size()},
                      {"triangles", triangles},
                      {"load_s", load_s},
                      {"settle_and_upload_s", settle_and_upload_s},
                      {"settle_simulated_s", simulator.settle_result().simulated_time_s},
                      {"fps_640x480_depth_colour", rate(depth_colour, 60)},
                      {"fps_640x480_depth_only", rate(depth_only, 60)},
                      {"fps_640x480_depth_colour_instances", rate(all, 60)},
                      {"vivid_scans_per_s", scans("vivid", 10)},
                      {"pioneer_scans_per_s", scans("pioneer", 5)}};
  std::cout << j.dump(2) << "\n";
  return 0;
}
