#pragma once
// One simulated acquisition: the range image in the internal format (exactly what a sensor
// driver produces) plus the ground truth needed to score every later stage.
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "artisan/core/camera.hpp"
#include "artisan/core/range_image.hpp"
#include "artisan/sim/workcell.hpp"

namespace artisan::sim {

struct EnvironmentReading {
  double time_s = 0.0;                      ///< simulated clock [s since the epoch]
  Transform T_world_rig = Transform::Identity();  ///< where the rig was
  double dose_rate_uSv_per_h = 0.0;         ///< gamma dose rate [µSv/h]
  double temperature_C = 0.0;               ///< [°C]
  double humidity_percent = 0.0;            ///< relative humidity [%]
};

struct ObjectTruth {
  int instance_id = 0;
  std::string name;
  std::string model;             ///< the library model it is an instance of (Body::model); "" for none
  BodyRole role = BodyRole::structure;
  Transform T_world_object = Transform::Identity();
  int visible_pixels = 0;        ///< pixels of this instance in the acquisition's instance image that the sensor can measure
  /// pixels it covers when rendered alone from the same view, on an image plane three times as
  /// wide and high as the sensor's (what lies outside the frame is not seen either)
  int unoccluded_pixels = 0;
  double visible_fraction = 0.0; ///< visible / unoccluded (0 when out of view)
};

struct GroundTruth {
  std::string sensor_name;
  std::string sensor_kind;
  uint64_t seed = 0;
  double time_s = 0.0;                            ///< acquisition time [s since the epoch]
  Transform T_world_sensor = Transform::Identity();
  PinholeCamera camera;                           ///< the range image's pixel grid (sensor frame = its camera frame)
  std::vector<uint16_t> instance_ids;             ///< per range pixel; 0 = nothing
  std::vector<float> depth_m;                     ///< noise-free z per range pixel [m]; 0 = nothing
  std::vector<ObjectTruth> objects;               ///< every body, in workcell order
  std::map<std::string, double> joint_values;     ///< e.g. pan/tilt [rad], when the sensor moved
  std::optional<EnvironmentReading> environment;  ///< readings taken with the acquisition
};

struct Acquisition {
  RangeImage range;   ///< the internal format; sensor info carries kind, name, time and pose
  GroundTruth truth;
};

/// Writes DIR/range.ari, range.png (depth, 16-bit, 0.1 mm units, 0 = no data), one PNG per camera
/// image (<name>.png), and the ground truth: truth.json (poses, visible fractions, camera,
/// environment), instances.png (16-bit ids), depth_truth.png (16-bit, 0.1 mm) and truth.ari
/// (the noise-free range image, exact floats). Creates DIR. Throws artisan::FileError.
void write_acquisition(const Acquisition& acquisition, const std::filesystem::path& dir);

/// PNG writers (8-bit grey/RGB/RGBA, or 16-bit grey). Written atomically.
void write_png(const ColorImage& image, const std::filesystem::path& path);
void write_png16(int width, int height, const std::vector<uint16_t>& pixels, const std::filesystem::path& path);
/// Reads a 16-bit grey PNG (e.g. instances.png). Throws artisan::FileError.
std::vector<uint16_t> read_png16(const std::filesystem::path& path, int& width, int& height);

/// The ground truth of one view: the sensor's kind, seed, pose and pixel grid, the noise-free
/// instance ids and depth, and every body's pose and visible fraction (each body rendered alone,
/// instance pass only, from the same view). Name, time, joints and environment are the caller's.
/// `measurable` (per pixel, empty: all) marks the pixels the sensor can measure at all - for a
/// triangulation scanner those in its range, lit by its laser and met by its rays short of the
/// incidence where every return drops out: a surface in the laser's shadow, or seen edge-on,
/// gives no data, so it is not visible, however plainly the camera sees it.
class Renderer;
GroundTruth view_truth(Renderer& renderer, const Workcell& cell, const std::string& sensor_kind, uint64_t seed,
                       const PinholeCamera& camera, const Transform& T_world_sensor, std::vector<uint16_t> instance_ids,
                       std::vector<float> depth_m, double near_m, double far_m, const std::vector<char>& measurable = {});

}  // namespace artisan::sim
