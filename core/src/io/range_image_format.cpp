// The ".ari" range-image format: a sealed blob (blob_container.hpp) whose payload (version 1), in order:
//   i32 width, i32 height
//   sensor: string kind, string name, f64 timestamp_s, u8 has_pose [+ 16 f64 row-major],
//           u32 n_attributes, n x (string key, string value)
//   validity bitmask: ceil(w*h/8) bytes, bit i%8 of byte i/8 for pixel i
//   n_valid x (f32 x, f32 y, f32 z)   points of valid pixels, in pixel order
//   n_valid x (f32 u, f32 v)          uv of valid pixels; invalid pixels decode to their
//                                     pixel coordinates
//   u32 n_images, n x (string name, i32 w, i32 h, i32 channels, bytes, u8 has_camera
//                      [+ i32 w, i32 h, f64 fx, fy, cx, cy], 16 f64 T_sensor_camera)
// Invalid pixels are not stored: they decode to (0, 0, 0) with uv = pixel coordinates, the
// canonical form RangeImage::empty_of_size() makes.
#include "artisan/core/io/range_image_format.hpp"

#include <algorithm>
#include <cstring>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"
#include "artisan/core/io/blob_container.hpp"
#include "artisan/core/io/bytes.hpp"
#include "binary_fields.hpp"

namespace artisan::io {

namespace {

constexpr BlobMagic kMagic = {'A', 'R', 'T', 'I', 'S', 'R', 'I', '\x1a'};
constexpr int kMaxSide = detail::kMaxImageSide;
using detail::get_transform;
using detail::put_transform;

}  // namespace

bool is_range_image_blob(std::span<const uint8_t> bytes) {
  return has_magic(bytes, kMagic);
}

std::vector<uint8_t> encode_range_image(const RangeImage& image, const RangeImageEncoding& encoding) {
  image.validate();
  ByteWriter w;
  w.put<int32_t>(image.width);
  w.put<int32_t>(image.height);
  const auto& s = image.sensor;
  w.put_string(s.kind);
  w.put_string(s.name);
  w.put<double>(s.timestamp_s);
  w.put<uint8_t>(s.T_world_sensor.has_value());
  if (s.T_world_sensor) put_transform(w, *s.T_world_sensor);
  w.put<uint32_t>(static_cast<uint32_t>(s.attributes.size()));
  for (const auto& [k, v] : s.attributes) {
    w.put_string(k);
    w.put_string(v);
  }
  std::vector<uint8_t> mask((image.pixel_count() + 7) / 8, 0);
  for (size_t i = 0; i < image.pixel_count(); ++i)
    if (image.valid[i]) mask[i / 8] |= static_cast<uint8_t>(1u << (i % 8));
  w.put_bytes(mask);
  for (size_t i = 0; i < image.pixel_count(); ++i)
    if (image.valid[i]) w.put_array(image.points_sensor[i].data(), 3);
  for (size_t i = 0; i < image.pixel_count(); ++i)
    if (image.valid[i]) w.put_array(image.uv[i].data(), 2);
  w.put<uint32_t>(static_cast<uint32_t>(image.images.size()));
  for (const auto& cam : image.images) {
    w.put_string(cam.name);
    detail::put_image(w, cam.image);
    w.put<uint8_t>(cam.camera.has_value());
    if (cam.camera) {
      w.put<int32_t>(cam.camera->width);
      w.put<int32_t>(cam.camera->height);
      for (double v : {cam.camera->fx, cam.camera->fy, cam.camera->cx, cam.camera->cy}) w.put<double>(v);
    }
    put_transform(w, cam.T_sensor_camera);
  }
  return seal_blob(kMagic, kRangeImageFormatVersion, w.bytes(), encoding.compress);
}

RangeImage decode_range_image(std::span<const uint8_t> bytes, const std::string& source) {
  const auto raw = open_blob(bytes, kMagic, kRangeImageFormatVersion, "range image", source);
  ByteReader r(raw, source);
  const int width = r.get<int32_t>("width");
  const int height = r.get<int32_t>("height");
  if (width <= 0 || height <= 0 || width > kMaxSide || height > kMaxSide)
    r.fail("size", std::to_string(width) + " x " + std::to_string(height) + " is not a valid image size");
  RangeImage image = RangeImage::empty_of_size(width, height);
  auto& s = image.sensor;
  s.kind = r.get_string("sensor kind");
  s.name = r.get_string("sensor name");
  s.timestamp_s = r.get<double>("timestamp");
  if (r.get<uint8_t>("has_pose")) s.T_world_sensor = get_transform(r, "T_world_sensor");
  const auto n_attr = r.get<uint32_t>("attribute count");
  if (n_attr > r.remaining() / 8) r.fail("attribute count", std::to_string(n_attr) + " is more than the payload can hold");
  for (uint32_t i = 0; i < n_attr; ++i) {
    auto key = r.get_string("attribute key");
    s.attributes[key] = r.get_string("attribute value");
  }
  std::vector<uint8_t> mask((image.pixel_count() + 7) / 8);
  r.get_array(mask.data(), mask.size(), "validity mask");
  for (size_t i = 0; i < image.pixel_count(); ++i) image.valid[i] = (mask[i / 8] >> (i % 8)) & 1;
  for (size_t i = 0; i < image.pixel_count(); ++i)
    if (image.valid[i]) r.get_array(image.points_sensor[i].data(), 3, "points");
  for (size_t i = 0; i < image.pixel_count(); ++i)
    if (image.valid[i]) r.get_array(image.uv[i].data(), 2, "uv");
  const auto n_images = r.get<uint32_t>("image count");
  if (n_images > 64) r.fail("image count", std::to_string(n_images) + " exceeds 64");
  for (uint32_t i = 0; i < n_images; ++i) {
    CameraImage cam;
    cam.name = r.get_string("image name");
    cam.image = detail::get_image(r);
    if (r.get<uint8_t>("has_camera")) {
      PinholeCamera c;
      c.width = r.get<int32_t>("camera width");
      c.height = r.get<int32_t>("camera height");
      c.fx = r.get<double>("fx");
      c.fy = r.get<double>("fy");
      c.cx = r.get<double>("cx");
      c.cy = r.get<double>("cy");
      cam.camera = c;
    }
    cam.T_sensor_camera = get_transform(r, "T_sensor_camera");
    image.images.push_back(std::move(cam));
  }
  if (r.remaining() != 0) r.fail("payload", std::to_string(r.remaining()) + " unexpected bytes at the end");
  try {
    image.validate();
  } catch (const Error& e) {
    throw Error(source + ": " + e.what());
  }
  return image;
}

void write_range_image(const RangeImage& image, const std::filesystem::path& path) {
  write_file_atomically(path, encode_range_image(image));
}

RangeImage read_range_image(const std::filesystem::path& path) {
  return decode_range_image(read_file_bytes(path), path.string());
}

}  // namespace artisan::io
