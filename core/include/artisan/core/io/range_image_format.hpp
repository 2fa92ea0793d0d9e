#pragma once
// The project's own compact binary range-image format (".ari"), for storage and transport.
//
// A sealed blob (blob_container.hpp) with magic "ARTISRI\x1a".
// The payload holds the size, sensor info, the points/uv of valid pixels only, a validity
// bitmask and the camera images; see range_image_format.cpp. Decoding checks every size and the
// checksum, so a corrupt or truncated blob always throws.
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "artisan/core/range_image.hpp"

namespace artisan::io {

inline constexpr uint32_t kRangeImageFormatVersion = 1;

struct RangeImageEncoding {
  bool compress = true;  ///< deflate the payload (zlib level 1)
};

std::vector<uint8_t> encode_range_image(const RangeImage& image, const RangeImageEncoding& encoding = {});
/// `source` names the blob in error messages (a file path, "workspace object 12", ...).
RangeImage decode_range_image(std::span<const uint8_t> bytes, const std::string& source);
/// True when the bytes start with the format's magic.
bool is_range_image_blob(std::span<const uint8_t> bytes);

void write_range_image(const RangeImage& image, const std::filesystem::path& path);
RangeImage read_range_image(const std::filesystem::path& path);

}  // namespace artisan::io
