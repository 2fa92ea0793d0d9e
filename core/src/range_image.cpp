#include "artisan/core/range_image.hpp"

#include <string>

#include "artisan/core/error.hpp"

namespace artisan {

namespace {
bool same_transform(const Transform& a, const Transform& b) { return a.matrix() == b.matrix(); }
}  // namespace

bool CameraImage::operator==(const CameraImage& o) const {
  auto same_camera = [](const std::optional<PinholeCamera>& a, const std::optional<PinholeCamera>& b) {
    if (a.has_value() != b.has_value()) return false;
    if (!a) return true;
    return a->width == b->width && a->height == b->height && a->fx == b->fx && a->fy == b->fy && a->cx == b->cx &&
           a->cy == b->cy;
  };
  return name == o.name && image == o.image && same_camera(camera, o.camera) &&
         same_transform(T_sensor_camera, o.T_sensor_camera);
}

bool SensorInfo::operator==(const SensorInfo& o) const {
  if (T_world_sensor.has_value() != o.T_world_sensor.has_value()) return false;
  if (T_world_sensor && !same_transform(*T_world_sensor, *o.T_world_sensor)) return false;
  return kind == o.kind && name == o.name && timestamp_s == o.timestamp_s && attributes == o.attributes;
}

RangeImage RangeImage::empty_of_size(int width, int height) {
  if (width <= 0 || height <= 0) {
    throw Error("range image size " + std::to_string(width) + " x " + std::to_string(height) + " is not positive");
  }
  RangeImage image;
  image.width = width;
  image.height = height;
  image.points_sensor.assign(image.pixel_count(), Eigen::Vector3f::Zero());
  image.valid.assign(image.pixel_count(), 0);
  image.uv.resize(image.pixel_count());
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) image.uv[image.index(x, y)] = Eigen::Vector2f(x, y);
  return image;
}

size_t RangeImage::valid_count() const {
  size_t n = 0;
  for (uint8_t v : valid) n += v != 0;
  return n;
}

Eigen::AlignedBox3f RangeImage::bounds() const {
  Eigen::AlignedBox3f box;
  for (size_t i = 0; i < points_sensor.size(); ++i)
    if (valid[i]) box.extend(points_sensor[i]);
  return box;
}

void RangeImage::validate() const {
  const size_t n = pixel_count();
  if (width < 0 || height < 0) throw Error("range image: negative size");
  if (points_sensor.size() != n || uv.size() != n || valid.size() != n) {
    throw Error("range image " + std::to_string(width) + " x " + std::to_string(height) + ": has " +
                std::to_string(points_sensor.size()) + " points, " + std::to_string(uv.size()) + " uv, " +
                std::to_string(valid.size()) + " validity flags; expected " + std::to_string(n) + " each");
  }
  for (size_t i = 0; i < n; ++i) {
    if (valid[i] && !points_sensor[i].allFinite()) {
      throw Error("range image: pixel (" + std::to_string(i % width) + ", " + std::to_string(i / width) +
                  ") is marked valid but its point is not finite");
    }
  }
  for (const auto& cam : images) {
    const auto& im = cam.image;
    if (im.channels != 1 && im.channels != 3 && im.channels != 4)
      throw Error("range image: camera image \"" + cam.name + "\" has " + std::to_string(im.channels) + " channels");
    if (im.pixels.size() != static_cast<size_t>(im.width) * im.height * im.channels)
      throw Error("range image: camera image \"" + cam.name + "\" pixel buffer does not match its size");
  }
}

bool RangeImage::operator==(const RangeImage& o) const {
  return width == o.width && height == o.height && points_sensor == o.points_sensor && uv == o.uv &&
         valid == o.valid && sensor == o.sensor && images == o.images;
}

}  // namespace artisan
