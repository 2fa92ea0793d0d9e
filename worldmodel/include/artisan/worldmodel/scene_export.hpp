#pragma once
// The world model for other robot software: the environment and each recognized object as a
// link (URDF), a static model (SDF) or a node (glTF), at its pose, with its mesh; each robot with
// its links' collision geometry: in URDF its own tree (names prefixed "ROBOT_") fixed to the
// world at its root pose, in SDF a model of its links (at the zero configuration) and joints fixed
// to the world, in glTF its links at the current joint values. URDF and SDF carry no joint state:
// the current joint values are written as a comment.
#include <filesystem>
#include <string>
#include <vector>

#include "artisan/worldmodel/world_model.hpp"

namespace artisan::worldmodel {

enum class SceneFormat { urdf, sdf, gltf };
/// Throws artisan::Error listing the formats when `name` is none of them.
SceneFormat scene_format_from_string(const std::string& name);

/// Writes the scene into `dir` (created when missing): URDF "scene.urdf" or SDF "scene.sdf"
/// with binary STL meshes under "meshes/" (referenced by relative paths), or glTF "scene.gltf"
/// (+ ".bin"). Returns the files written. Files are written atomically one by one; on failure
/// what was written is removed.
std::vector<std::filesystem::path> export_scene(const WorldModel& world, SceneFormat format, const std::filesystem::path& dir);

}  // namespace artisan::worldmodel
