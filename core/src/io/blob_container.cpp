#include "artisan/core/io/blob_container.hpp"

#include <zlib.h>

#include <algorithm>
#include <cstring>

#include "artisan/core/error.hpp"
#include "artisan/core/io/bytes.hpp"

namespace artisan::io {

namespace {
constexpr size_t kHeaderSize = 8 + 4 + 4 + 8 + 8 + 4;
}

uint32_t crc32_of(std::span<const uint8_t> data) {
  uLong crc = crc32(0L, Z_NULL, 0);
  size_t done = 0;
  while (done < data.size()) {  // zlib takes uInt lengths
    const auto n = static_cast<uInt>(std::min<size_t>(data.size() - done, 1u << 30));
    crc = crc32(crc, data.data() + done, n);
    done += n;
  }
  return static_cast<uint32_t>(crc);
}

bool has_magic(std::span<const uint8_t> bytes, const BlobMagic& magic) {
  return bytes.size() >= magic.size() && std::memcmp(bytes.data(), magic.data(), magic.size()) == 0;
}

std::vector<uint8_t> seal_blob(const BlobMagic& magic, uint32_t version, std::span<const uint8_t> payload, bool compress) {
  std::vector<uint8_t> packed;
  if (compress) {
    uLongf n = compressBound(payload.size());
    packed.resize(n);
    if (compress2(packed.data(), &n, payload.data(), payload.size(), 1) != Z_OK) throw Error("compression failed");
    packed.resize(n);
  }
  const std::span<const uint8_t> body = compress ? std::span<const uint8_t>(packed) : payload;
  ByteWriter out;
  out.put_array(magic.data(), magic.size());
  out.put<uint32_t>(version);
  out.put<uint32_t>(compress ? 1u : 0u);
  out.put<uint64_t>(payload.size());
  out.put<uint64_t>(body.size());
  out.put<uint32_t>(crc32_of(body));
  out.put_bytes(body);
  return std::move(out.bytes());
}

std::vector<uint8_t> open_blob(std::span<const uint8_t> bytes, const BlobMagic& magic, uint32_t version,
                               const std::string& what, const std::string& source) {
  if (bytes.empty()) throw Error(source + ": empty " + what + " blob");
  if (!has_magic(bytes, magic)) throw Error(source + ": not an Artisan " + what + " (bad magic)");
  ByteReader h(bytes, source);
  for (size_t i = 0; i < magic.size(); ++i) h.get<uint8_t>("magic");
  const auto found = h.get<uint32_t>("version");
  if (found != version)
    h.fail("version", std::to_string(found) + " is not supported (this build reads " + what + " version " + std::to_string(version) + ")");
  const auto flags = h.get<uint32_t>("flags");
  if (flags & ~1u) h.fail("flags", "unknown flags " + std::to_string(flags));
  const auto raw_size = h.get<uint64_t>("raw_size");
  const auto data_size = h.get<uint64_t>("data_size");
  const auto crc = h.get<uint32_t>("crc32");
  if (data_size != h.remaining())
    h.fail("data_size", "header says " + std::to_string(data_size) + " bytes of payload, " + std::to_string(h.remaining()) + " present");
  const std::span<const uint8_t> body = bytes.subspan(kHeaderSize);
  if (crc32_of(body) != crc) throw Error(source + ": checksum mismatch (corrupt " + what + ")");
  if (!(flags & 1)) {
    if (raw_size != data_size) h.fail("raw_size", "uncompressed payload size " + std::to_string(raw_size) + " differs from " + std::to_string(data_size));
    return {body.begin(), body.end()};
  }
  // Deflate cannot expand by more than 1032:1; a larger claim is corruption, refused before
  // allocating.
  if (raw_size > data_size * 1032 + 64) h.fail("raw_size", std::to_string(raw_size) + " is impossible for " + std::to_string(data_size) + " compressed bytes");
  std::vector<uint8_t> raw(raw_size);
  uLongf n = raw_size;
  if (uncompress(raw.data(), &n, body.data(), body.size()) != Z_OK || n != raw_size)
    throw Error(source + ": corrupt " + what + " payload (decompression failed)");
  return raw;
}

}  // namespace artisan::io
