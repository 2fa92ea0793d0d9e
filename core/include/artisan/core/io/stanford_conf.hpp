#pragma once
// Stanford 3D Scanning Repository ".conf" files: "camera tx ty tz qx qy qz qw" and
// "bmesh FILE tx ty tz qx qy qz qw". The scan-to-world transform is p_world = R(q)^T p_scan + t
// (the conjugate of q), checked numerically on the bunny scans (tests/core/test_stanford_conf).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "artisan/core/pose.hpp"

namespace artisan::io {

struct StanfordScanPose {
  std::string file;         ///< as written in the .conf, relative to the .conf's folder
  Transform T_world_scan;
};

struct StanfordConf {
  std::optional<Transform> T_world_camera;  ///< the "camera" line, when present
  std::vector<StanfordScanPose> scans;
  /// The pose of the scan named `file`; throws artisan::Error when absent.
  const StanfordScanPose& scan(const std::string& file) const;
};

StanfordConf read_stanford_conf(const std::filesystem::path& path);

}  // namespace artisan::io
