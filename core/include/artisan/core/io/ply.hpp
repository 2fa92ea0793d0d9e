#pragma once
// PLY (Stanford polygon file format): ASCII, binary little and big endian, any elements and
// properties, scalar or list. Geometry conversions (meshes, point clouds, Cyberware range
// grids) sit on top of this generic layer.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "artisan/core/range_image.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::io {

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };
enum class PlyType : uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;       ///< value type (item type for lists)
  std::optional<PlyType> list_count_type;  ///< set for list properties
  std::vector<double> values;              ///< scalar: one per element; list: all items
  std::vector<uint32_t> list_offsets;      ///< list: element i's items are [off[i], off[i+1])

  bool is_list() const { return list_count_type.has_value(); }
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> properties;

  const PlyProperty* find(const std::string& property) const;
  PlyProperty* find(const std::string& property);
};

struct PlyFile {
  PlyFormat format = PlyFormat::kBinaryLittleEndian;
  std::vector<std::string> comments;
  std::vector<std::pair<std::string, std::string>> obj_info;  ///< "obj_info KEY VALUE" lines
  std::vector<PlyElement> elements;

  const PlyElement* find(const std::string& element) const;
};

/// Parses a PLY file from memory; `source` names it in error messages.
/// Throws artisan::FileError on any defect (bad header, truncated data, bad counts,
/// trailing bytes, numbers that do not fit their type).
PlyFile parse_ply(std::span<const uint8_t> bytes, const std::filesystem::path& source);
PlyFile read_ply(const std::filesystem::path& path);
std::vector<uint8_t> serialize_ply(const PlyFile& ply);
void write_ply(const PlyFile& ply, const std::filesystem::path& path);

// Geometry on top of PLY. `source` names the file in error messages.

/// True when the file holds a Cyberware range grid (element range_grid).
bool ply_has_range_grid(const PlyFile& ply);
/// The Cyberware range grid as a RangeImage (num_cols x num_rows from obj_info; grid row 0 is
/// the bottom scanline, so image row 0 is the last grid row). obj_info lines become
/// sensor attributes.
RangeImage ply_to_range_image(const PlyFile& ply, const std::filesystem::path& source);
/// Vertices (+ normals nx ny nz, colours red green blue, uv as u v / s t / texture_u texture_v)
/// and faces (vertex_indices or vertex_index; polygons are fan-triangulated).
TriangleMesh ply_to_mesh(const PlyFile& ply, const std::filesystem::path& source);
PointCloud ply_to_point_cloud(const PlyFile& ply, const std::filesystem::path& source);

PlyFile range_image_to_ply(const RangeImage& image, PlyFormat format);
PlyFile mesh_to_ply(const TriangleMesh& mesh, PlyFormat format);
PlyFile point_cloud_to_ply(const PointCloud& cloud, PlyFormat format);

}  // namespace artisan::io
