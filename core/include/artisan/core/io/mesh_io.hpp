#pragma once
// Meshes in the formats robot tools use. Reading: PLY (own reader) and OBJ, STL, COLLADA,
// glTF/GLB, OFF and the rest of what assimp reads. Writing: PLY, OBJ, glTF/GLB.
#include <filesystem>
#include <string>
#include <vector>

#include "artisan/core/triangle_mesh.hpp"

namespace artisan::io {

/// Reads every mesh in the file into one TriangleMesh in the file's frame (node transforms
/// applied; COLLADA up-axis ignored, unit scale applied). Per-vertex colours come from the
/// file or, failing that, from each material's diffuse colour.
/// Throws artisan::FileError when the file cannot be read or holds no triangles.
TriangleMesh read_mesh(const std::filesystem::path& path);

/// Writes by extension: .ply (binary), .obj, .stl (binary), .gltf, .glb. Written atomically: on failure
/// the destination is untouched.
void write_mesh(const TriangleMesh& mesh, const std::filesystem::path& path);

/// One mesh of a glTF scene, placed by T_parent_node under the scene root.
struct SceneNode {
  std::string name;
  const TriangleMesh* mesh = nullptr;
  Transform T_parent_node = Transform::Identity();
};
/// Writes several meshes as the nodes of one glTF scene (.gltf with its .bin, or .glb).
void write_gltf_scene(const std::vector<SceneNode>& nodes, const std::filesystem::path& path);

}  // namespace artisan::io
