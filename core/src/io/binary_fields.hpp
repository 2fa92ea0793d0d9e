#pragma once
// Private: fields shared by the project's binary formats (range images, meshes).
#include "artisan/core/error.hpp"
#include "artisan/core/image.hpp"
#include "artisan/core/io/bytes.hpp"
#include "artisan/core/pose.hpp"

namespace artisan::io::detail {

inline constexpr int kMaxImageSide = 1 << 15;

inline void put_transform(ByteWriter& w, const Transform& T) {
  for (double v : to_row_major(T)) w.put<double>(v);
}

inline Transform get_transform(ByteReader& r, const char* field) {
  std::array<double, 16> m{};
  for (auto& v : m) v = r.get<double>(field);
  try {
    return from_row_major(m);
  } catch (const Error& e) {
    r.fail(field, e.what());
  }
}

inline void put_image(ByteWriter& w, const ColorImage& image) {
  w.put<int32_t>(image.width);
  w.put<int32_t>(image.height);
  w.put<int32_t>(image.channels);
  w.put_bytes(image.pixels);
}

inline ColorImage get_image(ByteReader& r) {
  ColorImage image;
  image.width = r.get<int32_t>("image width");
  image.height = r.get<int32_t>("image height");
  image.channels = r.get<int32_t>("image channels");
  if (image.width < 0 || image.height < 0 || image.width > kMaxImageSide || image.height > kMaxImageSide ||
      (image.channels != 1 && image.channels != 3 && image.channels != 4))
    r.fail("image size", std::to_string(image.width) + " x " + std::to_string(image.height) + " x " +
                             std::to_string(image.channels) + " is not valid");
  image.pixels.resize(static_cast<size_t>(image.width) * image.height * image.channels);
  r.get_array(image.pixels.data(), image.pixels.size(), "image pixels");
  return image;
}

}  // namespace artisan::io::detail
