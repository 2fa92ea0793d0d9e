#pragma once
// Helpers shared by the tests: data paths, a temporary folder, nearest-neighbour distances,
// running the command line.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "artisan/core/error.hpp"

namespace artisan::test {

inline std::filesystem::path data_dir() { return ARTISAN_DATA_DIR; }
inline std::filesystem::path bunny_dir() { return data_dir() / "stanford-bunny"; }

inline const std::vector<std::string>& bunny_scans() {
  static const std::vector<std::string> scans = {"bun000", "bun045", "bun090", "bun180", "bun270",
                                                 "bun315", "chin",   "ear_back", "top2", "top3"};
  return scans;
}

/// A fresh folder under the system temp dir, removed when the object dies.
class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() / ("artisan-test-" + std::to_string(rd()) + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

/// Exact nearest-neighbour distances through a uniform hash grid (cell = search radius);
/// distances beyond the radius are reported as +inf.
class NearestNeighbours {
 public:
  NearestNeighbours(const std::vector<Eigen::Vector3f>& points, float radius) : points_(points), cell_(radius) {
    for (size_t i = 0; i < points_.size(); ++i) grid_[key(cell_of(points_[i]))].push_back(i);
  }
  float distance(const Eigen::Vector3f& q) const {
    const auto c = cell_of(q);
    float best = INFINITY;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          auto it = grid_.find(key({c[0] + dx, c[1] + dy, c[2] + dz}));
          if (it == grid_.end()) continue;
          for (size_t i : it->second) best = std::min(best, (points_[i] - q).norm());
        }
    return best <= cell_ ? best : INFINITY;
  }

 private:
  std::array<int, 3> cell_of(const Eigen::Vector3f& p) const {
    return {static_cast<int>(std::floor(p.x() / cell_)), static_cast<int>(std::floor(p.y() / cell_)),
            static_cast<int>(std::floor(p.z() / cell_))};
  }
  static uint64_t key(const std::array<int, 3>& c) {
    return (static_cast<uint64_t>(c[0] & 0x1fffff) << 42) | (static_cast<uint64_t>(c[1] & 0x1fffff) << 21) |
           static_cast<uint64_t>(c[2] & 0x1fffff);
  }
  const std::vector<Eigen::Vector3f>& points_;
  float cell_;
  std::unordered_map<uint64_t, std::vector<size_t>> grid_;
};

inline double median(std::vector<double> v) {
  auto mid = v.begin() + v.size() / 2;
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

struct CommandResult {
  int exit_code = -1;
  std::string out;  ///< stdout
  std::string err;  ///< stderr
};

/// Runs a shell command line, capturing stdout and stderr.
inline CommandResult run_command(const std::string& command_line) {
  static int counter = 0;
  const auto err_path = std::filesystem::temp_directory_path() /
                        ("artisan-test-stderr-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
  CommandResult r;
  FILE* pipe = ::popen((command_line + " 2>" + err_path.string()).c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) r.out.append(buf, n);
  const int status = ::pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  FILE* e = std::fopen(err_path.c_str(), "r");
  if (e) {
    while ((n = std::fread(buf, 1, sizeof buf, e)) > 0) r.err.append(buf, n);
    std::fclose(e);
  }
  std::filesystem::remove(err_path);
  return r;
}

/// The message of the artisan::Error `fn` throws ("" when it throws none).
template <typename Fn>
std::string error_of(Fn&& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace artisan::test
