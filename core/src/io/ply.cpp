// Generic PLY reading and writing. Geometry conversions are in ply_geometry.cpp.
#include "artisan/core/io/ply.hpp"

#include <algorithm>
#include <bit>
#include <cassert>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"

namespace artisan::io {

namespace {

struct TypeInfo {
  const char* name;
  size_t size;
  bool is_integer;
  double min;
  double max;
};

TypeInfo info(PlyType t) {
  switch (t) {
    case PlyType::kInt8: return {"char", 1, true, -128.0, 127.0};
    case PlyType::kUint8: return {"uchar", 1, true, 0.0, 255.0};
    case PlyType::kInt16: return {"short", 2, true, -32768.0, 32767.0};
    case PlyType::kUint16: return {"ushort", 2, true, 0.0, 65535.0};
    case PlyType::kInt32: return {"int", 4, true, -2147483648.0, 2147483647.0};
    case PlyType::kUint32: return {"uint", 4, true, 0.0, 4294967295.0};
    case PlyType::kFloat32: return {"float", 4, false, -std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    case PlyType::kFloat64: return {"double", 8, false, -std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  }
  return {"?", 0, false, 0, 0};
}

std::optional<PlyType> type_from_name(const std::string& s) {
  if (s == "char" || s == "int8") return PlyType::kInt8;
  if (s == "uchar" || s == "uint8") return PlyType::kUint8;
  if (s == "short" || s == "int16") return PlyType::kInt16;
  if (s == "ushort" || s == "uint16") return PlyType::kUint16;
  if (s == "int" || s == "int32") return PlyType::kInt32;
  if (s == "uint" || s == "uint32") return PlyType::kUint32;
  if (s == "float" || s == "float32") return PlyType::kFloat32;
  if (s == "double" || s == "float64") return PlyType::kFloat64;
  return std::nullopt;
}

std::vector<std::string> split_words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> words;
  for (std::string w; in >> w;) words.push_back(w);
  return words;
}

[[noreturn]] void fail(const std::filesystem::path& source, const std::string& what) { throw FileError(source, what); }

// Parses the header; returns the offset of the first body byte.
size_t parse_header(std::span<const uint8_t> bytes, const std::filesystem::path& source, PlyFile& ply) {
  if (bytes.empty()) fail(source, "empty file");
  if (bytes.size() < 4 || std::memcmp(bytes.data(), "ply", 3) != 0 || (bytes[3] != '\n' && bytes[3] != '\r'))
    fail(source, "not a PLY file (does not start with \"ply\")");
  size_t pos = 0;
  int line_no = 0;
  bool have_format = false;
  constexpr size_t kMaxHeader = 1 << 20;
  while (true) {
    if (pos >= bytes.size() || pos > kMaxHeader) fail(source, "header has no end_header line");
    size_t eol = pos;
    while (eol < bytes.size() && bytes[eol] != '\n') ++eol;
    if (eol >= bytes.size()) fail(source, "header has no end_header line");
    std::string line(reinterpret_cast<const char*>(bytes.data() + pos), eol - pos);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    pos = eol + 1;
    ++line_no;
    const auto where = "header line " + std::to_string(line_no) + " \"" + line.substr(0, 80) + "\"";
    const auto words = split_words(line);
    if (line_no == 1) continue;  // "ply"
    if (words.empty()) continue;
    const std::string& key = words[0];
    if (key == "end_header") break;
    if (key == "format") {
      if (words.size() != 3) fail(source, where + ": expected \"format TYPE VERSION\"");
      if (words[1] == "ascii") ply.format = PlyFormat::kAscii;
      else if (words[1] == "binary_little_endian") ply.format = PlyFormat::kBinaryLittleEndian;
      else if (words[1] == "binary_big_endian") ply.format = PlyFormat::kBinaryBigEndian;
      else fail(source, where + ": unknown format \"" + words[1] + "\"");
      if (words[2] != "1.0") fail(source, where + ": unsupported version " + words[2]);
      have_format = true;
    } else if (key == "comment") {
      ply.comments.push_back(line.size() > 8 ? line.substr(8) : "");
    } else if (key == "obj_info") {
      if (words.size() < 2) fail(source, where + ": empty obj_info");
      const auto value_at = line.find(words[1]) + words[1].size();
      auto value = line.substr(value_at);
      value.erase(0, value.find_first_not_of(" \t"));
      ply.obj_info.emplace_back(words[1], value);
    } else if (key == "element") {
      if (words.size() != 3) fail(source, where + ": expected \"element NAME COUNT\"");
      size_t count = 0;
      const auto& c = words[2];
      auto [p, ec] = std::from_chars(c.data(), c.data() + c.size(), count);
      if (ec != std::errc() || p != c.data() + c.size()) fail(source, where + ": count \"" + c + "\" is not a non-negative integer");
      ply.elements.push_back({words[1], count, {}});
    } else if (key == "property") {
      if (ply.elements.empty()) fail(source, where + ": property before any element");
      PlyProperty prop;
      if (words.size() == 5 && words[1] == "list") {
        const auto count_type = type_from_name(words[2]);
        const auto item_type = type_from_name(words[3]);
        if (!count_type || !info(*count_type).is_integer) fail(source, where + ": bad list count type \"" + words[2] + "\"");
        if (!item_type) fail(source, where + ": unknown type \"" + words[3] + "\"");
        prop.list_count_type = count_type;
        prop.type = *item_type;
        prop.name = words[4];
      } else if (words.size() == 3) {
        const auto type = type_from_name(words[1]);
        if (!type) fail(source, where + ": unknown type \"" + words[1] + "\"");
        prop.type = *type;
        prop.name = words[2];
      } else {
        fail(source, where + ": expected \"property TYPE NAME\" or \"property list COUNT_TYPE ITEM_TYPE NAME\"");
      }
      ply.elements.back().properties.push_back(std::move(prop));
    } else {
      fail(source, where + ": unknown keyword \"" + key + "\"");
    }
  }
  if (!have_format) fail(source, "header has no format line");
  for (const auto& e : ply.elements)
    if (e.count > 0 && e.properties.empty()) fail(source, "element " + e.name + " has " + std::to_string(e.count) + " entries but no properties");
  return pos;
}

void check_range(double v, PlyType t, const std::filesystem::path& source, const PlyElement& e, size_t i,
                 const PlyProperty& p) {
  const auto ti = info(t);
  if (ti.is_integer && (v != std::floor(v) || v < ti.min || v > ti.max)) {
    fail(source, "element " + e.name + " " + std::to_string(i) + ", property " + p.name + ": value " +
                     std::to_string(v) + " does not fit type " + ti.name);
  }
}

class AsciiBody {
 public:
  AsciiBody(std::span<const uint8_t> bytes, size_t pos, const std::filesystem::path& source)
      : p_(reinterpret_cast<const char*>(bytes.data()) + pos),
        end_(reinterpret_cast<const char*>(bytes.data()) + bytes.size()),
        source_(source) {}

  double next(const PlyElement& e, size_t i, const PlyProperty& prop) {
    while (p_ < end_ && std::isspace(static_cast<unsigned char>(*p_))) ++p_;
    if (p_ >= end_) fail(source_, "truncated: element " + e.name + " " + std::to_string(i) + " of " + std::to_string(e.count) + ", property " + prop.name + " is missing");
    double v = 0;
    auto [q, ec] = std::from_chars(p_, end_, v);
    if (ec != std::errc() || (q < end_ && !std::isspace(static_cast<unsigned char>(*q)))) {
      const char* w = p_;
      while (w < end_ && !std::isspace(static_cast<unsigned char>(*w)) && w - p_ < 24) ++w;
      fail(source_, "element " + e.name + " " + std::to_string(i) + ", property " + prop.name + ": \"" + std::string(p_, w) + "\" is not a number");
    }
    p_ = q;
    return v;
  }
  size_t remaining() const { return static_cast<size_t>(end_ - p_); }
  bool only_whitespace_left() const {
    for (const char* q = p_; q < end_; ++q)
      if (!std::isspace(static_cast<unsigned char>(*q))) return false;
    return true;
  }

 private:
  const char* p_;
  const char* end_;
  const std::filesystem::path& source_;
};

class BinaryBody {
 public:
  BinaryBody(std::span<const uint8_t> bytes, size_t pos, bool swap, const std::filesystem::path& source)
      : bytes_(bytes), pos_(pos), swap_(swap), source_(source) {}

  double next(PlyType t, const PlyElement& e, size_t i, const PlyProperty& prop) {
    const size_t n = info(t).size;
    if (pos_ + n > bytes_.size()) fail(source_, "truncated: element " + e.name + " " + std::to_string(i) + " of " + std::to_string(e.count) + ", property " + prop.name + " is missing");
    uint8_t buf[8];
    std::memcpy(buf, bytes_.data() + pos_, n);
    if (swap_) std::reverse(buf, buf + n);
    pos_ += n;
    switch (t) {
      case PlyType::kInt8: return static_cast<int8_t>(buf[0]);
      case PlyType::kUint8: return buf[0];
      case PlyType::kInt16: { int16_t v; std::memcpy(&v, buf, 2); return v; }
      case PlyType::kUint16: { uint16_t v; std::memcpy(&v, buf, 2); return v; }
      case PlyType::kInt32: { int32_t v; std::memcpy(&v, buf, 4); return v; }
      case PlyType::kUint32: { uint32_t v; std::memcpy(&v, buf, 4); return v; }
      case PlyType::kFloat32: { float v; std::memcpy(&v, buf, 4); return v; }
      case PlyType::kFloat64: { double v; std::memcpy(&v, buf, 8); return v; }
    }
    return 0;
  }
  size_t remaining() const { return bytes_.size() - pos_; }

 private:
  std::span<const uint8_t> bytes_;
  size_t pos_;
  bool swap_;
  const std::filesystem::path& source_;
};

template <typename Body, typename Next>
void read_elements(PlyFile& ply, Body& body, Next next, size_t min_bytes_per_value, const std::filesystem::path& source) {
  for (auto& e : ply.elements) {
    // Refuse absurd counts before allocating: every value takes at least min_bytes_per_value.
    size_t min_bytes = 0;
    for (const auto& p : e.properties)
      min_bytes += p.is_list() ? (min_bytes_per_value == 1 ? 2 : info(*p.list_count_type).size)
                               : (min_bytes_per_value == 1 ? 2 : info(p.type).size);
    if (min_bytes > 0 && e.count > body.remaining() / min_bytes + 1) {
      fail(source, "truncated: element " + e.name + " declares " + std::to_string(e.count) + " entries, but only " +
                       std::to_string(body.remaining()) + " bytes remain");
    }
    for (auto& p : e.properties) {
      if (p.is_list()) {
        p.list_offsets.reserve(e.count + 1);
        p.list_offsets.push_back(0);
        p.values.reserve(e.count * 3);
      } else {
        p.values.reserve(e.count);
      }
    }
    for (size_t i = 0; i < e.count; ++i) {
      for (auto& p : e.properties) {
        if (!p.is_list()) {
          const double v = next(p.type, e, i, p);
          check_range(v, p.type, source, e, i, p);
          p.values.push_back(v);
          continue;
        }
        const double n = next(*p.list_count_type, e, i, p);
        check_range(n, *p.list_count_type, source, e, i, p);
        if (n < 0) fail(source, "element " + e.name + " " + std::to_string(i) + ", list " + p.name + ": negative length " + std::to_string(n));
        const auto count = static_cast<size_t>(n);
        if (count > body.remaining()) fail(source, "truncated: element " + e.name + " " + std::to_string(i) + ", list " + p.name + " of " + std::to_string(count) + " items runs past the end of the file");
        for (size_t k = 0; k < count; ++k) {
          const double v = next(p.type, e, i, p);
          check_range(v, p.type, source, e, i, p);
          p.values.push_back(v);
        }
        if (p.values.size() > std::numeric_limits<uint32_t>::max()) fail(source, "list " + p.name + " holds more than 2^32 items");
        p.list_offsets.push_back(static_cast<uint32_t>(p.values.size()));
      }
    }
  }
}

}  // namespace

const PlyProperty* PlyElement::find(const std::string& property) const {
  for (const auto& p : properties)
    if (p.name == property) return &p;
  return nullptr;
}

PlyProperty* PlyElement::find(const std::string& property) {
  for (auto& p : properties)
    if (p.name == property) return &p;
  return nullptr;
}

const PlyElement* PlyFile::find(const std::string& element) const {
  for (const auto& e : elements)
    if (e.name == element) return &e;
  return nullptr;
}

PlyFile parse_ply(std::span<const uint8_t> bytes, const std::filesystem::path& source) {
  PlyFile ply;
  const size_t body_start = parse_header(bytes, source, ply);
  if (ply.format == PlyFormat::kAscii) {
    AsciiBody body(bytes, body_start, source);
    read_elements(ply, body, [&](PlyType, const PlyElement& e, size_t i, const PlyProperty& p) { return body.next(e, i, p); }, 1, source);
    if (!body.only_whitespace_left()) fail(source, "unexpected data after the last element");
  } else {
    const bool swap = (ply.format == PlyFormat::kBinaryBigEndian) != (std::endian::native == std::endian::big);
    BinaryBody body(bytes, body_start, swap, source);
    read_elements(ply, body, [&](PlyType t, const PlyElement& e, size_t i, const PlyProperty& p) { return body.next(t, e, i, p); }, 0, source);
    if (body.remaining() != 0) fail(source, std::to_string(body.remaining()) + " unexpected bytes after the last element");
  }
  return ply;
}

PlyFile read_ply(const std::filesystem::path& path) { return parse_ply(read_file_bytes(path), path); }

namespace {

void append_ascii(std::string& out, double v, PlyType t) {
  char buf[64];
  std::to_chars_result r;
  if (t == PlyType::kFloat32) r = std::to_chars(buf, buf + sizeof buf, static_cast<float>(v));
  else if (t == PlyType::kFloat64) r = std::to_chars(buf, buf + sizeof buf, v);
  else r = std::to_chars(buf, buf + sizeof buf, static_cast<long long>(v));
  out.append(buf, r.ptr);
}

void append_binary(std::vector<uint8_t>& out, double v, PlyType t, bool swap) {
  uint8_t buf[8];
  size_t n = info(t).size;
  switch (t) {
    case PlyType::kInt8: { auto x = static_cast<int8_t>(v); std::memcpy(buf, &x, 1); break; }
    case PlyType::kUint8: { auto x = static_cast<uint8_t>(v); std::memcpy(buf, &x, 1); break; }
    case PlyType::kInt16: { auto x = static_cast<int16_t>(v); std::memcpy(buf, &x, 2); break; }
    case PlyType::kUint16: { auto x = static_cast<uint16_t>(v); std::memcpy(buf, &x, 2); break; }
    case PlyType::kInt32: { auto x = static_cast<int32_t>(v); std::memcpy(buf, &x, 4); break; }
    case PlyType::kUint32: { auto x = static_cast<uint32_t>(v); std::memcpy(buf, &x, 4); break; }
    case PlyType::kFloat32: { auto x = static_cast<float>(v); std::memcpy(buf, &x, 4); break; }
    case PlyType::kFloat64: { std::memcpy(buf, &v, 8); break; }
  }
  if (swap) std::reverse(buf, buf + n);
  out.insert(out.end(), buf, buf + n);
}

}  // namespace

std::vector<uint8_t> serialize_ply(const PlyFile& ply) {
  std::string header = "ply\nformat ";
  header += ply.format == PlyFormat::kAscii ? "ascii" : ply.format == PlyFormat::kBinaryLittleEndian ? "binary_little_endian" : "binary_big_endian";
  header += " 1.0\n";
  for (const auto& c : ply.comments) header += "comment " + c + "\n";
  for (const auto& [k, v] : ply.obj_info) header += "obj_info " + k + " " + v + "\n";
  for (const auto& e : ply.elements) {
    header += "element " + e.name + " " + std::to_string(e.count) + "\n";
    for (const auto& p : e.properties) {
      assert(p.is_list() ? p.list_offsets.size() == e.count + 1 : p.values.size() == e.count);
      header += "property ";
      if (p.is_list()) header += std::string("list ") + info(*p.list_count_type).name + " ";
      header += std::string(info(p.type).name) + " " + p.name + "\n";
    }
  }
  header += "end_header\n";
  std::vector<uint8_t> out(header.begin(), header.end());
  const bool swap = (ply.format == PlyFormat::kBinaryBigEndian) != (std::endian::native == std::endian::big);
  std::string line;
  for (const auto& e : ply.elements) {
    for (size_t i = 0; i < e.count; ++i) {
      line.clear();
      for (const auto& p : e.properties) {
        auto emit = [&](double v, PlyType t) {
          if (ply.format == PlyFormat::kAscii) {
            if (!line.empty()) line += ' ';
            append_ascii(line, v, t);
          } else {
            append_binary(out, v, t, swap);
          }
        };
        if (!p.is_list()) {
          emit(p.values[i], p.type);
          continue;
        }
        const uint32_t begin = p.list_offsets[i], end = p.list_offsets[i + 1];
        emit(end - begin, *p.list_count_type);
        for (uint32_t k = begin; k < end; ++k) emit(p.values[k], p.type);
      }
      if (ply.format == PlyFormat::kAscii) {
        line += '\n';
        out.insert(out.end(), line.begin(), line.end());
      }
    }
  }
  return out;
}

void write_ply(const PlyFile& ply, const std::filesystem::path& path) { write_file_atomically(path, serialize_ply(ply)); }

}  // namespace artisan::io
