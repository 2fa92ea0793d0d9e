// PCL PCD v0.7 reading and writing.
#include "artisan/core/io/pcd.hpp"

#include <algorithm>
#include <charconv>
#include <functional>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"

namespace artisan::io {

namespace {

[[noreturn]] void fail(const std::filesystem::path& source, const std::string& what) { throw FileError(source, what); }

struct Field {
  std::string name;
  int size = 4;
  char type = 'F';
  size_t count = 1;
  size_t offset = 0;  // byte offset within a point (binary) or value index within a line (ascii)
};

struct Header {
  std::vector<Field> fields;
  size_t width = 0, height = 0, points = 0;
  std::string data;
  size_t point_bytes = 0;
  size_t values_per_point = 0;
};

// LZF decompression (the format of PCD's binary_compressed), bounds-checked.
std::vector<uint8_t> lzf_decompress(std::span<const uint8_t> in, size_t out_size, const std::filesystem::path& source) {
  std::vector<uint8_t> out(out_size);
  size_t ip = 0, op = 0;
  while (ip < in.size()) {
    const unsigned ctrl = in[ip++];
    if (ctrl < 32) {
      const size_t len = ctrl + 1;
      if (ip + len > in.size() || op + len > out_size) fail(source, "corrupt binary_compressed data (literal run overflows)");
      std::memcpy(out.data() + op, in.data() + ip, len);
      ip += len;
      op += len;
    } else {
      size_t len = ctrl >> 5;
      size_t back = (ctrl & 0x1f) << 8;
      if (len == 7) {
        if (ip >= in.size()) fail(source, "corrupt binary_compressed data (truncated)");
        len += in[ip++];
      }
      if (ip >= in.size()) fail(source, "corrupt binary_compressed data (truncated)");
      back += in[ip++];
      len += 2;
      if (back + 1 > op || op + len > out_size) fail(source, "corrupt binary_compressed data (back reference out of range)");
      size_t ref = op - back - 1;
      for (size_t k = 0; k < len; ++k) out[op++] = out[ref++];
    }
  }
  if (op != out_size) fail(source, "corrupt binary_compressed data (decompressed " + std::to_string(op) + " of " + std::to_string(out_size) + " bytes)");
  return out;
}

size_t to_size(const std::string& s, const std::string& what, const std::filesystem::path& source) {
  size_t v = 0;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || p != s.data() + s.size()) fail(source, what + " \"" + s + "\" is not a non-negative integer");
  return v;
}

size_t parse_header(std::span<const uint8_t> bytes, const std::filesystem::path& source, Header& h) {
  if (bytes.empty()) fail(source, "empty file");
  size_t pos = 0;
  std::vector<std::string> sizes, types, counts;
  bool have_points = false;
  while (h.data.empty()) {
    if (pos >= bytes.size() || pos > (1 << 16)) fail(source, "PCD header has no DATA line");
    size_t eol = pos;
    while (eol < bytes.size() && bytes[eol] != '\n') ++eol;
    std::string line(reinterpret_cast<const char*>(bytes.data() + pos), eol - pos);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    pos = std::min(eol + 1, bytes.size());
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    std::string key;
    in >> key;
    std::vector<std::string> words;
    for (std::string w; in >> w;) words.push_back(w);
    if (key == "VERSION") continue;
    if (key == "FIELDS" || key == "COLUMNS") {
      for (const auto& w : words) h.fields.push_back({w});
    } else if (key == "SIZE") sizes = words;
    else if (key == "TYPE") types = words;
    else if (key == "COUNT") counts = words;
    else if (key == "WIDTH" && words.size() == 1) h.width = to_size(words[0], "WIDTH", source);
    else if (key == "HEIGHT" && words.size() == 1) h.height = to_size(words[0], "HEIGHT", source);
    else if (key == "POINTS" && words.size() == 1) { h.points = to_size(words[0], "POINTS", source); have_points = true; }
    else if (key == "VIEWPOINT") continue;
    else if (key == "DATA" && words.size() == 1) {
      h.data = words[0];
      if (h.data != "ascii" && h.data != "binary" && h.data != "binary_compressed") fail(source, "unknown DATA type \"" + h.data + "\"");
    } else {
      fail(source, "not a PCD file, or a malformed header line \"" + line.substr(0, 60) + "\"");
    }
  }
  if (h.fields.empty()) fail(source, "PCD header has no FIELDS");
  if (sizes.size() != h.fields.size() || types.size() != h.fields.size())
    fail(source, "PCD header: FIELDS, SIZE and TYPE have different lengths");
  if (!counts.empty() && counts.size() != h.fields.size()) fail(source, "PCD header: COUNT and FIELDS have different lengths");
  if (h.width == 0 && h.height == 0 && !have_points) fail(source, "PCD header has no WIDTH/HEIGHT");
  if (h.height == 0) h.height = 1;
  if (!have_points) h.points = h.width * h.height;
  if (h.width > (1u << 24) || h.height > (1u << 24) || h.points != h.width * h.height)
    fail(source, "PCD header: POINTS " + std::to_string(h.points) + " is not WIDTH x HEIGHT = " + std::to_string(h.width) + " x " + std::to_string(h.height));
  for (size_t i = 0; i < h.fields.size(); ++i) {
    auto& f = h.fields[i];
    f.size = static_cast<int>(to_size(sizes[i], "SIZE", source));
    if (types[i].size() != 1) fail(source, "PCD TYPE \"" + types[i] + "\" is not I, U or F");
    f.type = types[i][0];
    f.count = counts.empty() ? 1 : to_size(counts[i], "COUNT", source);
    const bool ok = (f.type == 'F' && (f.size == 4 || f.size == 8)) ||
                    ((f.type == 'I' || f.type == 'U') && (f.size == 1 || f.size == 2 || f.size == 4 || f.size == 8));
    if (!ok || f.count == 0 || f.count > 4096) fail(source, "PCD field " + f.name + ": unsupported TYPE " + types[i] + " SIZE " + sizes[i] + " COUNT " + std::to_string(f.count));
    f.offset = h.data == "ascii" ? h.values_per_point : h.point_bytes;
    h.point_bytes += f.size * f.count;
    h.values_per_point += f.count;
  }
  return pos;
}

double decode_value(const uint8_t* p, const Field& f) {
  switch (f.type) {
    case 'F': if (f.size == 4) { float v; std::memcpy(&v, p, 4); return v; } else { double v; std::memcpy(&v, p, 8); return v; }
    case 'U':
      switch (f.size) {
        case 1: return *p;
        case 2: { uint16_t v; std::memcpy(&v, p, 2); return v; }
        case 4: { uint32_t v; std::memcpy(&v, p, 4); return v; }
        default: { uint64_t v; std::memcpy(&v, p, 8); return static_cast<double>(v); }
      }
    default:
      switch (f.size) {
        case 1: return static_cast<int8_t>(*p);
        case 2: { int16_t v; std::memcpy(&v, p, 2); return v; }
        case 4: { int32_t v; std::memcpy(&v, p, 4); return v; }
        default: { int64_t v; std::memcpy(&v, p, 8); return static_cast<double>(v); }
      }
  }
}

// rgb is stored as the bits of a float (or a uint32): 0x00RRGGBB.
Color3 unpack_rgb(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return Color3((v >> 16) & 0xff, (v >> 8) & 0xff, v & 0xff);
}

}  // namespace

std::variant<RangeImage, PointCloud> parse_pcd(std::span<const uint8_t> bytes, const std::filesystem::path& source) {
  Header h;
  const size_t body = parse_header(bytes, source, h);
  auto field = [&](const std::string& name) -> const Field* {
    for (const auto& f : h.fields)
      if (f.name == name) return &f;
    return nullptr;
  };
  const Field *fx = field("x"), *fy = field("y"), *fz = field("z");
  if (!fx || !fy || !fz) fail(source, "PCD has no x, y, z fields");
  const Field *nx = field("normal_x"), *ny = field("normal_y"), *nz = field("normal_z");
  const Field* frgb = field("rgb");
  if (!frgb) frgb = field("rgba");
  if (frgb && frgb->size != 4) frgb = nullptr;
  const size_t n = h.points;

  std::vector<Eigen::Vector3f> xyz(n), normals(nx && ny && nz ? n : 0);
  std::vector<Color3> colors(frgb ? n : 0);
  if (h.data == "ascii") {
    const char* p = reinterpret_cast<const char*>(bytes.data()) + body;
    const char* end = reinterpret_cast<const char*>(bytes.data()) + bytes.size();
    std::vector<double> values(h.values_per_point);
    std::vector<uint32_t> rgb_bits(frgb ? n : 0);
    for (size_t i = 0; i < n; ++i) {
      for (size_t k = 0; k < h.values_per_point; ++k) {
        while (p < end && std::isspace(static_cast<unsigned char>(*p))) ++p;
        if (p >= end) fail(source, "truncated: point " + std::to_string(i) + " of " + std::to_string(n) + " is incomplete");
        const char* start = p;
        while (p < end && !std::isspace(static_cast<unsigned char>(*p))) ++p;
        std::string tok(start, p);
        if (tok == "nan" || tok == "NaN" || tok == "-nan") { values[k] = std::numeric_limits<double>::quiet_NaN(); continue; }
        auto [q, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), values[k]);
        if (ec != std::errc() || q != tok.data() + tok.size()) fail(source, "point " + std::to_string(i) + ": \"" + tok.substr(0, 24) + "\" is not a number");
      }
      xyz[i] = Eigen::Vector3f(values[fx->offset], values[fy->offset], values[fz->offset]);
      if (!normals.empty()) normals[i] = Eigen::Vector3f(values[nx->offset], values[ny->offset], values[nz->offset]);
      if (frgb) {
        // ASCII rgb is written as the float whose bits hold the colour, or as an integer.
        const double v = values[frgb->offset];
        uint32_t bits;
        if (frgb->type == 'F') { const float f = static_cast<float>(v); std::memcpy(&bits, &f, 4); }
        else bits = static_cast<uint32_t>(v);
        colors[i] = unpack_rgb(reinterpret_cast<const uint8_t*>(&bits));
      }
    }
    while (p < end && std::isspace(static_cast<unsigned char>(*p))) ++p;
    if (p != end) fail(source, "unexpected data after the last point");
  } else {
    std::span<const uint8_t> data = bytes.subspan(body);
    std::vector<uint8_t> unpacked;
    const bool soa = h.data == "binary_compressed";
    if (soa) {
      if (data.size() < 8) fail(source, "truncated: binary_compressed data has no size header");
      uint32_t packed_size, raw_size;
      std::memcpy(&packed_size, data.data(), 4);
      std::memcpy(&raw_size, data.data() + 4, 4);
      if (raw_size != n * h.point_bytes) fail(source, "binary_compressed: uncompressed size " + std::to_string(raw_size) + " does not match " + std::to_string(n) + " points of " + std::to_string(h.point_bytes) + " bytes");
      if (packed_size > data.size() - 8) fail(source, "truncated: binary_compressed data needs " + std::to_string(packed_size) + " bytes, " + std::to_string(data.size() - 8) + " present");
      unpacked = lzf_decompress(data.subspan(8, packed_size), raw_size, source);
      data = unpacked;
    } else if (data.size() < n * h.point_bytes) {
      fail(source, "truncated: binary data needs " + std::to_string(n * h.point_bytes) + " bytes, " + std::to_string(data.size()) + " present");
    } else if (data.size() > n * h.point_bytes) {
      fail(source, std::to_string(data.size() - n * h.point_bytes) + " unexpected bytes after the last point");
    }
    // Binary is array-of-structures; binary_compressed is structure-of-arrays.
    auto at = [&](const Field& f, size_t i) -> const uint8_t* {
      return soa ? data.data() + f.offset * n + i * f.size * f.count : data.data() + i * h.point_bytes + f.offset;
    };
    for (size_t i = 0; i < n; ++i) {
      xyz[i] = Eigen::Vector3f(decode_value(at(*fx, i), *fx), decode_value(at(*fy, i), *fy), decode_value(at(*fz, i), *fz));
      if (!normals.empty()) normals[i] = Eigen::Vector3f(decode_value(at(*nx, i), *nx), decode_value(at(*ny, i), *ny), decode_value(at(*nz, i), *nz));
      if (frgb) colors[i] = unpack_rgb(at(*frgb, i));
    }
  }

  if (h.height > 1) {  // organized: a range image
    RangeImage image = RangeImage::empty_of_size(static_cast<int>(h.width), static_cast<int>(h.height));
    for (size_t i = 0; i < n; ++i) {
      const bool nan = std::isnan(xyz[i].x()) || std::isnan(xyz[i].y()) || std::isnan(xyz[i].z());
      if (nan) continue;
      if (!xyz[i].allFinite()) fail(source, "point " + std::to_string(i) + " is infinite");
      image.points_sensor[i] = xyz[i];
      image.valid[i] = 1;
    }
    image.sensor.kind = "pcd";
    if (frgb) {
      CameraImage cam{"color", {static_cast<int>(h.width), static_cast<int>(h.height), 3, {}}, std::nullopt, Transform::Identity()};
      cam.image.pixels.reserve(n * 3);
      for (const auto& c : colors) cam.image.pixels.insert(cam.image.pixels.end(), {c[0], c[1], c[2]});
      image.images.push_back(std::move(cam));
    }
    return image;
  }
  PointCloud cloud;
  for (size_t i = 0; i < n; ++i) {
    if (std::isnan(xyz[i].x()) || std::isnan(xyz[i].y()) || std::isnan(xyz[i].z())) continue;  // "no return"
    if (!xyz[i].allFinite()) fail(source, "point " + std::to_string(i) + " is infinite");
    cloud.points.push_back(xyz[i]);
    if (!normals.empty()) cloud.normals.push_back(normals[i]);
    if (frgb) cloud.colors.push_back(colors[i]);
  }
  return cloud;
}

std::variant<RangeImage, PointCloud> read_pcd(const std::filesystem::path& path) { return parse_pcd(read_file_bytes(path), path); }

namespace {

void write_pcd_impl(const std::filesystem::path& path, PcdFormat format, size_t width, size_t height,
                    const std::function<bool(size_t, Eigen::Vector3f&, Color3&)>& point, bool with_rgb) {
  std::string header = "# .PCD v0.7 - Point Cloud Data file format (written by Artisan)\nVERSION 0.7\n";
  header += with_rgb ? "FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n" : "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
  header += "WIDTH " + std::to_string(width) + "\nHEIGHT " + std::to_string(height) + "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " +
            std::to_string(width * height) + "\nDATA " + (format == PcdFormat::kAscii ? "ascii" : "binary") + "\n";
  std::vector<uint8_t> out(header.begin(), header.end());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (size_t i = 0; i < width * height; ++i) {
    Eigen::Vector3f p;
    Color3 c(0, 0, 0);
    if (!point(i, p, c)) p = Eigen::Vector3f(nan, nan, nan);
    const uint32_t rgb = (uint32_t{c[0]} << 16) | (uint32_t{c[1]} << 8) | c[2];
    if (format == PcdFormat::kAscii) {
      std::string line;
      char buf[32];
      for (int k = 0; k < 3; ++k) {
        if (std::isnan(p[k])) line += "nan";
        else line.append(buf, std::to_chars(buf, buf + sizeof buf, p[k]).ptr);
        line += ' ';
      }
      if (with_rgb) line += std::to_string(rgb);
      else line.pop_back();
      line += '\n';
      out.insert(out.end(), line.begin(), line.end());
    } else {
      const auto* b = reinterpret_cast<const uint8_t*>(p.data());
      out.insert(out.end(), b, b + 12);
      if (with_rgb) out.insert(out.end(), reinterpret_cast<const uint8_t*>(&rgb), reinterpret_cast<const uint8_t*>(&rgb) + 4);
    }
  }
  write_file_atomically(path, out);
}

}  // namespace

void write_pcd(const RangeImage& image, const std::filesystem::path& path, PcdFormat format) {
  image.validate();
  const CameraImage* color = nullptr;
  for (const auto& cam : image.images)
    if (cam.image.width == image.width && cam.image.height == image.height && cam.image.channels >= 3) color = &cam;
  write_pcd_impl(path, format, image.width, image.height, [&](size_t i, Eigen::Vector3f& p, Color3& c) {
    if (color) {
      const uint8_t* px = color->image.pixels.data() + i * color->image.channels;
      c = Color3(px[0], px[1], px[2]);
    }
    p = image.points_sensor[i];
    return image.valid[i] != 0;
  }, color != nullptr);
}

void write_pcd(const PointCloud& cloud, const std::filesystem::path& path, PcdFormat format) {
  cloud.validate();
  write_pcd_impl(path, format, cloud.points.size(), 1, [&](size_t i, Eigen::Vector3f& p, Color3& c) {
    p = cloud.points[i];
    if (!cloud.colors.empty()) c = cloud.colors[i];
    return true;
  }, !cloud.colors.empty());
}

}  // namespace artisan::io
