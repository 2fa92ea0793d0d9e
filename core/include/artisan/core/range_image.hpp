#pragma once
// The internal range-image format: one sensor acquisition. Per pixel: x, y, z in the sensor
// frame [m], u, v into the associated camera image [pixels], and a validity flag. Pixels are
// row-major, row 0 at the top of the image.
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "artisan/core/camera.hpp"
#include "artisan/core/image.hpp"
#include "artisan/core/pose.hpp"

namespace artisan {

/// A camera image taken with the acquisition (Vivid: one colour image; Pioneer: three).
struct CameraImage {
  std::string name;                      ///< e.g. "color", "left", "right", "top"
  ColorImage image;
  std::optional<PinholeCamera> camera;   ///< intrinsics, when known
  Transform T_sensor_camera = Transform::Identity();
  bool operator==(const CameraImage& o) const;
};

/// What took the acquisition and how.
struct SensorInfo {
  std::string kind;    ///< e.g. "cyberware-3030ms", "minolta-vivid-700", "pioneer-trinocular"
  std::string name;    ///< the sensor instance
  double timestamp_s = 0.0;                        ///< acquisition time [s since the epoch], 0 if unknown
  std::optional<Transform> T_world_sensor;         ///< sensor pose at acquisition, when known
  std::map<std::string, std::string> attributes;  ///< free-form metadata (e.g. Cyberware obj_info)
  bool operator==(const SensorInfo& o) const;
};

struct RangeImage {
  int width = 0;
  int height = 0;
  std::vector<Eigen::Vector3f> points_sensor;  ///< width*height; (0,0,0) where invalid
  std::vector<Eigen::Vector2f> uv;             ///< width*height pixel coordinates in images[0]
  std::vector<uint8_t> valid;                  ///< width*height; 1 = measured, 0 = no data
  SensorInfo sensor;
  std::vector<CameraImage> images;

  /// An all-invalid image of the given size with uv = pixel coordinates.
  static RangeImage empty_of_size(int width, int height);

  size_t index(int x, int y) const { return static_cast<size_t>(y) * width + x; }
  size_t pixel_count() const { return static_cast<size_t>(width) * height; }
  size_t valid_count() const;
  /// Bounding box of the valid points (empty box when there are none).
  Eigen::AlignedBox3f bounds() const;
  /// Throws artisan::Error when sizes disagree or a valid point is not finite.
  void validate() const;
  bool operator==(const RangeImage& o) const;
};

}  // namespace artisan
