#pragma once
// Point Cloud Library PCD files (version 0.7): DATA ascii, binary and binary_compressed (LZF).
// Organized clouds (HEIGHT > 1) are range images; NaN points are invalid pixels.
#include <filesystem>
#include <span>
#include <variant>

#include "artisan/core/range_image.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::io {

enum class PcdFormat { kAscii, kBinary };

/// An organized PCD becomes a RangeImage (rgb/rgba fields become a colour image of the same
/// size, uv = pixel coordinates); an unorganized one a PointCloud (with normals/colours if
/// present). Throws artisan::FileError on any defect.
std::variant<RangeImage, PointCloud> parse_pcd(std::span<const uint8_t> bytes,
                                               const std::filesystem::path& source);
std::variant<RangeImage, PointCloud> read_pcd(const std::filesystem::path& path);

/// Writes an organized PCD (x y z, plus rgb when the image has a colour image of its size).
void write_pcd(const RangeImage& image, const std::filesystem::path& path, PcdFormat format);
void write_pcd(const PointCloud& cloud, const std::filesystem::path& path, PcdFormat format);

}  // namespace artisan::io
