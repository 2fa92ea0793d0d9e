// Workspace import throughput: the ten real bunny scans imported into a fresh workspace (read
// the PLY, encode, one transaction), and the workspace's size on disk against the raw files.
// Output: JSON on stdout.
#include <sys/utsname.h>
#include <unistd.h>

#include <algorithm>

#include <chrono>
#include <filesystem>
#include <iostream>

#include <nlohmann/json.hpp>

#include "artisan/core/io/geometry_file.hpp"
#include "artisan/worldmodel/workspace.hpp"

namespace fs = std::filesystem;
using namespace artisan;

int main(int argc, char** argv) {
  const int repetitions = argc > 1 ? std::max(1, std::atoi(argv[1])) : 5;
  const fs::path bunny = fs::path(ARTISAN_DATA_DIR) / "stanford-bunny";
  const std::vector<std::string> scans = {"bun000", "bun045", "bun090", "bun180", "bun270", "bun315", "chin", "ear_back", "top2", "top3"};
  uintmax_t raw_bytes = 0;
  for (const auto& s : scans) raw_bytes += fs::file_size(bunny / (s + ".ply"));
  const fs::path dir = fs::temp_directory_path() / ("artisan-bench-store-" + std::to_string(::getpid()));
  fs::create_directories(dir);

  std::vector<double> seconds;
  uintmax_t db_bytes = 0;
  for (int rep = 0; rep < repetitions; ++rep) {
    const auto db = dir / ("ws" + std::to_string(rep) + ".db");
    {
      auto ws = worldmodel::Workspace::create(db);
      const auto folder = ws.mkdir("/bunny");
      const auto t0 = std::chrono::steady_clock::now();
      ws.write([&] {
        for (const auto& s : scans) {
          const auto geometry = io::load_geometry(bunny / (s + ".ply"));
          ws.add(folder, worldmodel::make_image_object(s, std::get<RangeImage>(geometry), {"import", {{"source", s}}, {}}));
        }
      });
      seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }  // closing the workspace checkpoints the WAL into the database file
    db_bytes = fs::file_size(db);
  }
  fs::remove_all(dir);
  std::sort(seconds.begin(), seconds.end());
  const double median = seconds[seconds.size() / 2];
  utsname host{};
  uname(&host);
  nlohmann::json out = {
      {"benchmark", "store_import"},
      {"data", "10 Stanford bunny range scans (binary PLY, 512x400 range grids)"},
      {"machine", std::string(host.machine) + " " + host.release},
      {"repetitions", repetitions},
      {"seconds_median", median},
      {"seconds_min", seconds.front()},
      {"scans_per_second", scans.size() / median},
      {"megabytes_per_second", raw_bytes / 1e6 / median},
      {"raw_ply_bytes", raw_bytes},
      {"workspace_bytes", db_bytes},
      {"size_ratio_workspace_to_raw", static_cast<double>(db_bytes) / raw_bytes},
  };
  std::cout << out.dump(2) << "\n";
}
