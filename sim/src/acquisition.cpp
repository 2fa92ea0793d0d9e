#include "artisan/sim/acquisition.hpp"

#include <cmath>
#include <cstring>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"
#include "artisan/core/io/range_image_format.hpp"
#include "artisan/sim/renderer.hpp"

namespace artisan::sim {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

void write_mat(const cv::Mat& m, const fs::path& path) {
  std::vector<uint8_t> bytes;
  if (!cv::imencode(".png", m, bytes)) throw FileError(path, "cannot encode the PNG");
  io::write_file_atomically(path, bytes);
}

json pose_json(const Transform& T) {
  const auto m = to_row_major(T);
  return json(std::vector<double>(m.begin(), m.end()));
}

std::vector<uint16_t> depth_to_png(const std::vector<float>& depth_m) {
  std::vector<uint16_t> out(depth_m.size(), 0);
  for (size_t i = 0; i < depth_m.size(); ++i)
    if (depth_m[i] > 0) out[i] = static_cast<uint16_t>(std::clamp(std::lround(depth_m[i] * 1e4), 1l, 65535l));
  return out;
}

}  // namespace

void write_png(const ColorImage& image, const fs::path& path) {
  if (image.empty()) throw FileError(path, "empty image");
  const int type = image.channels == 1 ? CV_8UC1 : image.channels == 3 ? CV_8UC3 : CV_8UC4;
  cv::Mat m(image.height, image.width, type, const_cast<uint8_t*>(image.pixels.data()));
  cv::Mat bgr;
  if (image.channels == 3) cv::cvtColor(m, bgr, cv::COLOR_RGB2BGR);
  else if (image.channels == 4) cv::cvtColor(m, bgr, cv::COLOR_RGBA2BGRA);
  else bgr = m;
  write_mat(bgr, path);
}

void write_png16(int width, int height, const std::vector<uint16_t>& pixels, const fs::path& path) {
  if (pixels.size() != static_cast<size_t>(width) * height) throw FileError(path, "image size does not match its pixels");
  cv::Mat m(height, width, CV_16UC1, const_cast<uint16_t*>(pixels.data()));
  write_mat(m, path);
}

std::vector<uint16_t> read_png16(const fs::path& path, int& width, int& height) {
  const cv::Mat m = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  if (m.empty()) throw FileError(path, "cannot read the PNG");
  if (m.type() != CV_16UC1) throw FileError(path, "not a 16-bit grey PNG");
  width = m.cols;
  height = m.rows;
  std::vector<uint16_t> out(static_cast<size_t>(width) * height);
  for (int y = 0; y < height; ++y) std::memcpy(&out[static_cast<size_t>(y) * width], m.ptr<uint16_t>(y), width * 2);
  return out;
}

namespace {

std::vector<ObjectTruth> object_truth(Renderer& renderer, const Workcell& cell, const PinholeCamera& camera,
                                      const Transform& T_world_camera, const std::vector<uint16_t>& instance_ids,
                                      const std::vector<char>& measurable, double near_m, double far_m) {
  std::vector<int> visible(cell.bodies.size() + 1, 0);
  for (size_t i = 0; i < instance_ids.size(); ++i)
    if (const uint16_t id = instance_ids[i]; id > 0 && id <= cell.bodies.size() && (measurable.empty() || measurable[i])) ++visible[id];
  std::vector<ObjectTruth> out;
  // Alone, on an image plane three times as wide and high (same pixels, same principal ray): what
  // lies outside the sensor's frame counts as hidden too. A pipe half out of the frame is half
  // seen, not "0% occluded" (the recognition bench bands instances by this fraction).
  PinholeCamera wide = camera;
  wide.width = 3 * camera.width;
  wide.height = 3 * camera.height;
  wide.cx = camera.cx + camera.width;
  wide.cy = camera.cy + camera.height;
  RenderOptions alone;
  alone.color = false;
  alone.depth = false;
  alone.near_m = near_m;
  alone.far_m = far_m;
  for (const auto& b : cell.bodies) {
    ObjectTruth o;
    o.instance_id = b.instance_id;
    o.name = b.name;
    o.model = b.model;
    o.role = b.role;
    o.T_world_object = b.T_world_body;
    o.visible_pixels = visible[b.instance_id];
    alone.only_instance = b.instance_id;
    const auto r = renderer.render(cell, wide, T_world_camera, alone);
    for (uint16_t id : r.instance_ids) o.unoccluded_pixels += id == b.instance_id;
    o.visible_fraction = o.unoccluded_pixels > 0 ? static_cast<double>(o.visible_pixels) / o.unoccluded_pixels : 0.0;
    out.push_back(std::move(o));
  }
  return out;
}

}  // namespace

GroundTruth view_truth(Renderer& renderer, const Workcell& cell, const std::string& sensor_kind, uint64_t seed,
                       const PinholeCamera& camera, const Transform& T_world_sensor, std::vector<uint16_t> instance_ids,
                       std::vector<float> depth_m, double near_m, double far_m, const std::vector<char>& measurable) {
  if (!measurable.empty() && measurable.size() != instance_ids.size())
    throw Error("view_truth: " + std::to_string(measurable.size()) + " measurable flags for " + std::to_string(instance_ids.size()) + " pixels");
  GroundTruth t;
  t.sensor_kind = sensor_kind;
  t.seed = seed;
  t.T_world_sensor = T_world_sensor;
  t.camera = camera;
  t.objects = object_truth(renderer, cell, camera, T_world_sensor, instance_ids, measurable, near_m, far_m);
  t.instance_ids = std::move(instance_ids);
  t.depth_m = std::move(depth_m);
  return t;
}

void write_acquisition(const Acquisition& a, const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw FileError(dir, "cannot create the folder: " + ec.message());
  const RangeImage& r = a.range;
  const GroundTruth& t = a.truth;
  io::write_range_image(r, dir / "range.ari");
  std::vector<float> z(r.pixel_count(), 0.f);
  for (size_t i = 0; i < z.size(); ++i)
    if (r.valid[i]) z[i] = r.points_sensor[i].z();
  write_png16(r.width, r.height, depth_to_png(z), dir / "range.png");
  json images = json::array();
  for (const auto& cam : r.images) {
    write_png(cam.image, dir / (cam.name + ".png"));
    images.push_back(cam.name + ".png");
  }
  write_png16(t.camera.width, t.camera.height, t.instance_ids, dir / "instances.png");
  write_png16(t.camera.width, t.camera.height, depth_to_png(t.depth_m), dir / "depth_truth.png");
  RangeImage truth = RangeImage::empty_of_size(t.camera.width, t.camera.height);
  truth.sensor = r.sensor;
  truth.sensor.attributes["ground_truth"] = "noise-free";
  for (int v = 0; v < truth.height; ++v)
    for (int u = 0; u < truth.width; ++u) {
      const size_t i = truth.index(u, v);
      if (t.depth_m[i] <= 0) continue;
      truth.points_sensor[i] = t.camera.unproject({u, v}, t.depth_m[i]).cast<float>();
      truth.valid[i] = 1;
    }
  if (!r.uv.empty()) truth.uv = r.uv;
  io::write_range_image(truth, dir / "truth.ari");

  json j;
  j["sensor"] = {{"name", t.sensor_name}, {"kind", t.sensor_kind}};
  j["seed"] = t.seed;
  j["time_s"] = t.time_s;
  j["T_world_sensor"] = pose_json(t.T_world_sensor);
  j["camera"] = {{"width", t.camera.width}, {"height", t.camera.height}, {"fx", t.camera.fx}, {"fy", t.camera.fy},
                 {"cx", t.camera.cx}, {"cy", t.camera.cy}};
  j["joint_values"] = t.joint_values;
  json objects = json::array();
  for (const auto& o : t.objects)
    objects.push_back({{"instance_id", o.instance_id}, {"name", o.name}, {"model", o.model}, {"role", to_string(o.role)},
                       {"T_world_object", pose_json(o.T_world_object)}, {"visible_pixels", o.visible_pixels},
                       {"unoccluded_pixels", o.unoccluded_pixels}, {"visible_fraction", o.visible_fraction}});
  j["objects"] = objects;
  if (t.environment) {
    const auto& e = *t.environment;
    j["environment"] = {{"time_s", e.time_s}, {"T_world_rig", pose_json(e.T_world_rig)},
                        {"dose_rate_uSv_per_h", e.dose_rate_uSv_per_h}, {"temperature_C", e.temperature_C},
                        {"humidity_percent", e.humidity_percent}};
  }
  j["files"] = {{"range", "range.ari"}, {"range_png", "range.png"}, {"images", images}, {"instances", "instances.png"},
                {"depth_truth", "depth_truth.png"}, {"truth_range", "truth.ari"},
                {"png_depth_units_m", 1e-4}};
  const std::string text = j.dump(2) + "\n";
  io::write_file_atomically(dir / "truth.json", std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

}  // namespace artisan::sim
