#pragma once
// The project's compact binary mesh format (".amsh"), for storage and transport: a sealed blob
// (blob_container.hpp) with magic "ARTISMS\x1a". Lossless: vertices, normals, uv, colours,
// faces and the texture image.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "artisan/core/triangle_mesh.hpp"

namespace artisan::io {

inline constexpr uint32_t kMeshFormatVersion = 1;

std::vector<uint8_t> encode_mesh(const TriangleMesh& mesh, bool compress = true);
/// `source` names the blob in error messages. Throws artisan::Error on any defect.
TriangleMesh decode_mesh(std::span<const uint8_t> bytes, const std::string& source);

}  // namespace artisan::io
