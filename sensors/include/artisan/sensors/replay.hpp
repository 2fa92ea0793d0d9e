#pragma once
// File replay: recorded acquisitions served through the same path as live ones, so real data
// (e.g. the Stanford bunny's Cyberware range grids) reaches clients exactly as a sensor's would.
#include <atomic>
#include <filesystem>
#include <string>
#include <vector>

#include "artisan/sensors/sensor.hpp"

namespace artisan::sensors {

/// Serves the range images in a folder: `.ari`, PLY with a range grid, organized PCD, in file
/// name order. Parameter "file" picks one by name (with or without its extension); without it,
/// each acquisition serves the next file, cycling. The image is served as read, unchanged.
class ReplaySensor : public Sensor {
 public:
  /// Throws artisan::Error naming the folder when it is missing or holds no such file.
  ReplaySensor(const std::string& name, const std::filesystem::path& folder);
  SensorDescription describe() const override { return description_; }
  const std::vector<std::filesystem::path>& files() const { return files_; }

 protected:
  Acquisition do_acquire(const AcquireRequest& request, const CancelToken& cancel) override;

 private:
  SensorDescription description_;
  std::vector<std::filesystem::path> files_;
  std::atomic<size_t> next_{0};
};

}  // namespace artisan::sensors
