#pragma once
// Little-endian byte encoding with bounds checks, for the project's binary formats and
// protocols. ByteReader throws artisan::Error naming the source and the field on overrun.
#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "artisan/core/error.hpp"

namespace artisan::io {

class ByteWriter {
 public:
  template <typename T>
  void put(T value) {
    static_assert(std::is_arithmetic_v<T>);
    static_assert(std::endian::native == std::endian::little, "big-endian hosts not supported");
    const auto* p = reinterpret_cast<const uint8_t*>(&value);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  void put_string(const std::string& s) {
    put<uint32_t>(static_cast<uint32_t>(s.size()));
    bytes_.insert(bytes_.end(), s.begin(), s.end());
  }
  void put_bytes(std::span<const uint8_t> data) { bytes_.insert(bytes_.end(), data.begin(), data.end()); }
  template <typename T>
  void put_array(const T* data, size_t count) {
    if (count == 0) return;
    const auto* p = reinterpret_cast<const uint8_t*>(data);
    bytes_.insert(bytes_.end(), p, p + count * sizeof(T));
  }
  std::vector<uint8_t>& bytes() { return bytes_; }

 private:
  std::vector<uint8_t> bytes_;
};

class ByteReader {
 public:
  ByteReader(std::span<const uint8_t> bytes, std::string source) : bytes_(bytes), source_(std::move(source)) {}

  template <typename T>
  T get(const char* field) {
    static_assert(std::is_arithmetic_v<T>);
    need(sizeof(T), field);
    T value;
    std::memcpy(&value, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return value;
  }
  std::string get_string(const char* field, size_t max_size = 1u << 20) {
    const auto n = get<uint32_t>(field);
    if (n > max_size) fail(field, "length " + std::to_string(n) + " exceeds " + std::to_string(max_size));
    need(n, field);
    std::string s(reinterpret_cast<const char*>(bytes_.data() + pos_), n);
    pos_ += n;
    return s;
  }
  template <typename T>
  void get_array(T* out, size_t count, const char* field) {
    if (count == 0) return;  // out may be null for an empty array
    if (count > remaining() / sizeof(T)) fail(field, "needs " + std::to_string(count * sizeof(T)) + " bytes, " + std::to_string(remaining()) + " left");
    std::memcpy(out, bytes_.data() + pos_, count * sizeof(T));
    pos_ += count * sizeof(T);
  }
  size_t remaining() const { return bytes_.size() - pos_; }
  size_t position() const { return pos_; }
  [[noreturn]] void fail(const char* field, const std::string& what) const {
    throw Error(source_ + ": " + field + ": " + what + " (at byte " + std::to_string(pos_) + ")");
  }

 private:
  void need(size_t n, const char* field) const {
    if (n > remaining()) fail(field, "truncated: needs " + std::to_string(n) + " bytes, " + std::to_string(remaining()) + " left");
  }
  std::span<const uint8_t> bytes_;
  std::string source_;
  size_t pos_ = 0;
};

}  // namespace artisan::io
