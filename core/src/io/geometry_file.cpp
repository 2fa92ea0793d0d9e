#include "artisan/core/io/geometry_file.hpp"

#include <algorithm>
#include <cstring>
#include <fstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"
#include "artisan/core/io/mesh_io.hpp"
#include "artisan/core/io/pcd.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/range_image_format.hpp"

namespace artisan::io {

namespace {

std::optional<FileFormat> format_from_extension(const std::string& ext) {
  if (ext == ".ply") return FileFormat::kPly;
  if (ext == ".pcd") return FileFormat::kPcd;
  if (ext == ".ari") return FileFormat::kAri;
  if (ext == ".obj") return FileFormat::kObj;
  if (ext == ".stl") return FileFormat::kStl;
  if (ext == ".dae") return FileFormat::kCollada;
  if (ext == ".gltf") return FileFormat::kGltf;
  if (ext == ".glb") return FileFormat::kGlb;
  if (ext == ".off" || ext == ".3ds" || ext == ".fbx" || ext == ".x3d" || ext == ".3mf") return FileFormat::kOtherMesh;
  return std::nullopt;
}

}  // namespace

std::string to_string(FileFormat format) {
  switch (format) {
    case FileFormat::kPly: return "PLY";
    case FileFormat::kPcd: return "PCD";
    case FileFormat::kAri: return "Artisan range image";
    case FileFormat::kObj: return "OBJ";
    case FileFormat::kStl: return "STL";
    case FileFormat::kCollada: return "COLLADA";
    case FileFormat::kGltf: return "glTF";
    case FileFormat::kGlb: return "glTF binary";
    case FileFormat::kOtherMesh: return "mesh";
  }
  return "?";
}

FileFormat detect_format(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw FileError(path, "no such file");
  if (!std::filesystem::is_regular_file(path, ec)) throw FileError(path, "not a regular file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path, "cannot open");
  char head[16] = {};
  in.read(head, sizeof head);
  const auto n = in.gcount();
  if (n == 0) throw FileError(path, "empty file");
  if (n >= 4 && std::memcmp(head, "ply", 3) == 0 && (head[3] == '\n' || head[3] == '\r')) return FileFormat::kPly;
  if (is_range_image_blob(std::span(reinterpret_cast<const uint8_t*>(head), static_cast<size_t>(n)))) return FileFormat::kAri;
  const auto ext = lower_extension(path);
  if (const auto f = format_from_extension(ext)) {
    if (*f == FileFormat::kPly || *f == FileFormat::kAri) throw FileError(path, "has a " + ext + " extension but is not a " + to_string(*f) + " file");
    return *f;
  }
  throw FileError(path, "unknown file format \"" + ext + "\" (PLY, PCD, ARI, OBJ, STL, DAE, glTF/GLB, OFF, ...)");
}

FileFormat format_for_output(const std::filesystem::path& path) {
  const auto ext = lower_extension(path);
  const auto f = format_from_extension(ext);
  if (!f || *f == FileFormat::kStl || *f == FileFormat::kCollada || *f == FileFormat::kOtherMesh)
    throw Error(path.string() + ": cannot write \"" + ext + "\" files (write .ply, .pcd, .ari, .obj, .gltf or .glb)");
  return *f;
}

std::string kind_name(const Geometry& geometry) {
  switch (geometry.index()) {
    case 0: return "range image";
    case 1: return "mesh";
    default: return "point cloud";
  }
}

Geometry load_geometry(const std::filesystem::path& path) {
  switch (detect_format(path)) {
    case FileFormat::kPly: {
      const auto ply = read_ply(path);
      if (ply_has_range_grid(ply)) return ply_to_range_image(ply, path);
      if (const auto* face = ply.find("face"); face && face->count > 0) {
        auto mesh = ply_to_mesh(ply, path);
        try {
          mesh.validate();
        } catch (const Error& e) {
          throw FileError(path, e.what());
        }
        return mesh;
      }
      return ply_to_point_cloud(ply, path);
    }
    case FileFormat::kPcd: {
      auto v = read_pcd(path);
      if (auto* image = std::get_if<RangeImage>(&v)) return std::move(*image);
      return std::get<PointCloud>(std::move(v));
    }
    case FileFormat::kAri: return read_range_image(path);
    default: return read_mesh(path);
  }
}

void save_geometry(const Geometry& geometry, const std::filesystem::path& path) {
  const FileFormat format = format_for_output(path);
  auto refuse = [&]() {
    throw Error("cannot write a " + kind_name(geometry) + " as " + to_string(format) + " (" + path.string() + ")" +
                (geometry.index() == 0 ? ": mesh it first, or write .ply, .pcd or .ari" : ""));
  };
  if (const auto* image = std::get_if<RangeImage>(&geometry)) {
    if (format == FileFormat::kPly) write_ply(range_image_to_ply(*image, PlyFormat::kBinaryLittleEndian), path);
    else if (format == FileFormat::kPcd) write_pcd(*image, path, PcdFormat::kBinary);
    else if (format == FileFormat::kAri) write_range_image(*image, path);
    else refuse();
  } else if (const auto* mesh = std::get_if<TriangleMesh>(&geometry)) {
    if (format == FileFormat::kPcd || format == FileFormat::kAri) refuse();
    write_mesh(*mesh, path);
  } else {
    const auto& cloud = std::get<PointCloud>(geometry);
    if (format == FileFormat::kPly) write_ply(point_cloud_to_ply(cloud, PlyFormat::kBinaryLittleEndian), path);
    else if (format == FileFormat::kPcd) write_pcd(cloud, path, PcdFormat::kBinary);
    else refuse();
  }
}

}  // namespace artisan::io
