#pragma once
// The container shared by the project's binary formats (range images, meshes, ...): a typed,
// versioned, checksummed and optionally deflated payload.
//
// Layout (all integers little endian):
//   magic      8 bytes  names the content, e.g. "ARTISRI\x1a"
//   version    u32      of the payload layout
//   flags      u32      bit 0: payload deflate-compressed
//   raw_size   u64      size of the uncompressed payload
//   data_size  u64      size of the payload as stored
//   crc32      u32      CRC-32 of the payload as stored
//   payload    data_size bytes
// Opening checks every field and the checksum, so a corrupt or truncated blob always throws.
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace artisan::io {

using BlobMagic = std::array<char, 8>;

/// Wraps `payload`; deflates it (zlib level 1) when `compress`.
std::vector<uint8_t> seal_blob(const BlobMagic& magic, uint32_t version, std::span<const uint8_t> payload, bool compress);

/// The payload of a sealed blob. Throws artisan::Error naming `source` when the magic, version,
/// sizes or checksum are wrong. `what` names the content in messages ("range image").
std::vector<uint8_t> open_blob(std::span<const uint8_t> bytes, const BlobMagic& magic, uint32_t version,
                               const std::string& what, const std::string& source);

bool has_magic(std::span<const uint8_t> bytes, const BlobMagic& magic);

uint32_t crc32_of(std::span<const uint8_t> data);

}  // namespace artisan::io
