#pragma once
// 8-bit images (grey, RGB or RGBA), row-major, rows top to bottom.
#include <cstdint>
#include <vector>

namespace artisan {

struct ColorImage {
  int width = 0;
  int height = 0;
  int channels = 3;            ///< 1 (grey), 3 (RGB) or 4 (RGBA)
  std::vector<uint8_t> pixels;  ///< width * height * channels bytes, interleaved

  bool empty() const { return width == 0 || height == 0; }
  uint8_t* at(int x, int y) { return pixels.data() + (static_cast<size_t>(y) * width + x) * channels; }
  const uint8_t* at(int x, int y) const {
    return pixels.data() + (static_cast<size_t>(y) * width + x) * channels;
  }
  bool operator==(const ColorImage&) const = default;
};

}  // namespace artisan
