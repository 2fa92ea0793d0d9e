#pragma once
// Persistent occupancy grids in the workspace (perception/integration): a grid object holds its
// definition and the list of meshes distributed into it in its metadata, the meshes as its
// provenance inputs, and its blocks in the grid_blocks table, so a grid survives restarts and a
// scan can be added next week without redoing the others. Each operation is one transaction:
// bad input or a failure leaves the workspace as it was.
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "artisan/perception/block_store.hpp"
#include "artisan/perception/integration.hpp"
#include "artisan/worldmodel/workspace.hpp"

namespace artisan::worldmodel {

/// The blocks of one grid object. Writes join the caller's Workspace::write() when there is
/// one (the grid operations below group a whole distribution into one transaction).
class WorkspaceBlockStore final : public BlockStore {
 public:
  /// Throws artisan::Error when `grid` is not a grid object.
  WorkspaceBlockStore(Workspace& workspace, ObjectId grid);
  std::optional<std::vector<uint8_t>> load(const BlockKey& key) override;
  void store(const BlockKey& key, const std::vector<uint8_t>& bytes) override;
  std::vector<BlockKey> keys() override;

 private:
  Workspace& workspace_;
  ObjectId grid_;
};

/// How a mesh's sensor saw it, and where that came from.
struct MeshSensorView {
  SensorView view_mesh;
  std::string source;  ///< e.g. "image /b/bun000 (cyberware-3030ms): parallel rays"
};

/// The sensor view of a mesh, from its source image (see the comment in grid_store.cpp).
MeshSensorView sensor_view_of_mesh(const Workspace& workspace, ObjectId mesh);

/// One mesh distributed into a grid, as stored in the grid's metadata ("meshes").
struct GridMeshEntry {
  ObjectId mesh = 0;
  std::string path;                         ///< the mesh's path when it was added
  int mesh_index = 0;                       ///< texture channel under ChannelMode::kPerMesh
  Transform T_grid_mesh = Transform::Identity();
  SensorView view_mesh;
  std::string view_source;
  size_t points = 0;                        ///< surface samples that spread evidence
  std::string added_at;                     ///< ISO 8601, UTC
};

/// Progress of a long operation: `done` of `total` steps finished, `item` says what the last one
/// did (naming objects by path). Called on the calling thread; may be empty.
using ProgressFn = std::function<void(size_t done, size_t total, const std::string& item)>;

/// A new, empty grid object `name` in `folder`. Throws on a bad definition or name.
ObjectId create_grid(Workspace& workspace, ObjectId folder, const std::string& name, const GridDefinition& definition);
GridDefinition grid_definition(const Workspace& workspace, ObjectId grid);
std::vector<GridMeshEntry> grid_meshes(const Workspace& workspace, ObjectId grid);

struct AddToGridReport {
  GridMeshEntry entry;
  DistributeResult distribute;
  GridCacheStats cache;
  size_t blocks = 0;        ///< blocks the grid holds afterwards
  size_t block_bytes = 0;   ///< [bytes] their stored size
};

/// Distributes `mesh` into `grid` at T_grid_mesh (default: the mesh's T_world_mesh metadata when
/// it has one, else the identity). Refuses a mesh already in the grid, a non-mesh, a bad pose.
AddToGridReport add_to_grid(Workspace& workspace, ObjectId grid, ObjectId mesh,
                            const std::optional<Transform>& T_grid_mesh = std::nullopt);

struct ExtractGridReport {
  ObjectId merged = 0;    ///< the merged mesh object
  size_t vertices = 0;
  size_t faces = 0;
  size_t blocks = 0;      ///< blocks visited
  double seconds = 0.0;   ///< [s] extraction
};

/// Extracts the grid's surface as a merged mesh (kind mesh, subkind "merged", grid frame) named
/// `name` in `folder`; a new version when a merged mesh of that name exists there. Provenance:
/// operation "grid extract", the extraction parameters, inputs the grid and its meshes.
ExtractGridReport extract_grid(Workspace& workspace, ObjectId grid, ObjectId folder, const std::string& name,
                               const ExtractParams& params = {});

struct MergeReport {
  ObjectId grid = 0;
  std::vector<AddToGridReport> added;
  ExtractGridReport extract;
  double seconds = 0.0;  ///< [s] the whole merge
};

/// A MultiMesh merged: a grid `<MM>-grid` beside it (kept, so a scan can be added later), every
/// member distributed at its T_root_member (grid frame = the root member's frame), and the
/// merged mesh `<MM>-merged` beside it with provenance (operation "merge": the definition, the
/// members and their poses; inputs the multimesh, the grid and the meshes). Existing objects of
/// those names get a new version. One transaction.
MergeReport merge_multimesh(Workspace& workspace, ObjectId multimesh, const GridDefinition& definition,
                            const ExtractParams& params = {}, const ProgressFn& progress = {});

/// JSON forms (stored in metadata and provenance, printed by the command line).
nlohmann::json sensor_view_to_json(const SensorView& view);
SensorView sensor_view_from_json(const nlohmann::json& j);
nlohmann::json grid_mesh_entry_to_json(const GridMeshEntry& entry);

}  // namespace artisan::worldmodel
