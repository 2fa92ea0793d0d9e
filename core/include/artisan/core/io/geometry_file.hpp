#pragma once
// One entry point for "whatever geometry this file holds": format detection by content
// (PLY, PCD and .ari magic) and extension (assimp formats), loading and saving.
#include <filesystem>
#include <string>
#include <variant>

#include "artisan/core/range_image.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::io {

enum class FileFormat { kPly, kPcd, kAri, kObj, kStl, kCollada, kGltf, kGlb, kOtherMesh };

std::string to_string(FileFormat format);

/// Detects the format from the first bytes, then the extension. Throws artisan::FileError
/// for a missing, empty or unrecognised file.
FileFormat detect_format(const std::filesystem::path& path);
/// The format an output path asks for, by extension. Throws artisan::Error when unknown.
FileFormat format_for_output(const std::filesystem::path& path);

using Geometry = std::variant<RangeImage, TriangleMesh, PointCloud>;

std::string kind_name(const Geometry& geometry);  ///< "range image", "mesh", "point cloud"

/// Loads a file: PLY with a range grid, organized PCD and .ari are range images; PLY with
/// faces and assimp formats are meshes; PLY without faces and unorganized PCD point clouds.
Geometry load_geometry(const std::filesystem::path& path);
/// Saves by extension; throws artisan::Error when the format cannot hold that kind
/// (e.g. a range image as OBJ). Atomic: on failure the destination is untouched.
void save_geometry(const Geometry& geometry, const std::filesystem::path& path);

}  // namespace artisan::io
