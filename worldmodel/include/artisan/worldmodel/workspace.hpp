#pragma once
// The workspace: everything a user makes, as a tree of folders like a file explorer, kept in
// an SQL database with the parameters and inputs that made each object (provenance).
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "artisan/core/range_image.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/worldmodel/database.hpp"

namespace artisan::worldmodel {

using ObjectId = int64_t;

/// Object kinds of the original system (see ARCHITECTURE.md, "Data model").
enum class ObjectKind { kFolder, kImage, kMesh, kMultiMesh, kModel, kRecognizedModel, kGrid, kRobot };

std::string to_string(ObjectKind kind);
/// Throws artisan::Error listing the kinds when `name` is none of them.
ObjectKind object_kind_from_string(const std::string& name);

struct ObjectInfo {
  ObjectId id = 0;
  ObjectKind kind = ObjectKind::kFolder;
  std::string subkind;              ///< image: sensor kind; mesh: "original" or "merged"; robot: its URDF name
  std::optional<ObjectId> folder;   ///< the containing folder; none for the root
  std::string name;
  std::string path;                 ///< "/cell/east/bun000"; "/" for the root
  int version = 1;                  ///< reprocessing makes version n+1 beside version n
  std::optional<ObjectId> previous_version;
  std::string created_at;           ///< ISO 8601, UTC
  nlohmann::json metadata = nlohmann::json::object();
};

/// How a derived object was made: the operation, every parameter (defaults written out) and
/// the input objects.
struct Provenance {
  std::string operation;
  nlohmann::json parameters = nlohmann::json::object();
  std::vector<ObjectId> inputs;
};

/// A large datum stored with an object.
struct ObjectBlob {
  std::string role;       ///< e.g. "range_image", "mesh"
  std::string encoding;   ///< e.g. "artisan-range-image/1"
  SqlBlob data;
};

struct NewObject {
  ObjectKind kind = ObjectKind::kFolder;
  std::string subkind;
  std::string name;
  nlohmann::json metadata = nlohmann::json::object();
  std::vector<ObjectBlob> blobs;
  std::optional<Provenance> provenance;
};

/// An image object: the range image as its "range_image" data, its size and sensor as metadata.
NewObject make_image_object(const std::string& name, const RangeImage& image, const Provenance& provenance);
/// A mesh (kind kMesh, subkind "original"/"merged") or a model (kind kModel): the mesh as its
/// "mesh" data; vertex/face counts and resolution added to `metadata`.
NewObject make_mesh_object(ObjectKind kind, const std::string& subkind, const std::string& name, const TriangleMesh& mesh,
                           const Provenance& provenance, nlohmann::json metadata = nlohmann::json::object());

struct MultiMeshMember {
  int64_t member_id = 0;
  ObjectId mesh = 0;
  std::optional<int64_t> parent_member;  ///< none for the root member
  Transform T_parent_member = Transform::Identity();
  std::string method;                    ///< "spin", "icp", "manual", "root"
  nlohmann::json quality = nlohmann::json::object();
};

struct CheckReport {
  int schema_version = 0;
  size_t objects = 0;
  size_t blobs = 0;
  std::vector<std::string> problems;  ///< empty when the workspace is sound
};

/// Path rules: absolute ("/a/b"), components of letters, digits and "._-+@" (no "." or ".."
/// alone). Throws artisan::Error naming the path and the defect.
void validate_path(const std::string& path);
void validate_name(const std::string& name);

/// What has been committed to a workspace: `own` counts this Workspace object's commits,
/// `others` changes when any other connection commits (another process, another Workspace on
/// the same file). Equal stamps: nothing was committed in between.
struct ChangeStamp {
  int64_t own = 0, others = 0;
  bool operator==(const ChangeStamp&) const = default;
};

class Workspace {
 public:
  static constexpr int kSchemaVersion = 3;  ///< 2: grid blocks; 3: robot objects

  /// A new workspace file; throws artisan::Error when the file exists.
  static Workspace create(const std::filesystem::path& path);
  /// An existing workspace, migrated to the current schema; throws when it is missing, is not a
  /// workspace or was made by a newer build.
  static Workspace open(const std::filesystem::path& path);
  /// Over any backend; creates the schema on an empty database and migrates an old one.
  explicit Workspace(std::unique_ptr<Database> db);
  Workspace(Workspace&&) noexcept;
  Workspace& operator=(Workspace&&) noexcept;
  ~Workspace();

  // --- reading -------------------------------------------------------------------------------
  ObjectId root() const;
  int schema_version() const;
  ObjectInfo get(ObjectId id) const;
  /// "42" (an ID) or "/a/b" (a path; the latest version), or "/a/b@2" (version 2).
  ObjectInfo resolve(const std::string& id_or_path) const;
  /// The folder at `path`; throws when it is missing or not a folder.
  ObjectInfo folder(const std::string& path) const;
  /// Latest versions of the objects in a folder, ordered by name (folders first).
  std::vector<ObjectInfo> children(ObjectId folder) const;
  std::vector<ObjectInfo> versions(ObjectId id) const;  ///< every version of the same object, oldest first
  std::optional<Provenance> provenance(ObjectId id) const;
  std::vector<ObjectInfo> derived_from(ObjectId id) const;  ///< objects that list `id` as an input
  std::vector<ObjectBlob> blobs(ObjectId id) const;
  SqlBlob blob(ObjectId id, const std::string& role) const;
  RangeImage load_image(ObjectId id) const;
  TriangleMesh load_mesh(ObjectId id) const;   ///< a mesh or a model's mesh
  std::vector<MultiMeshMember> members(ObjectId multimesh) const;
  /// The bytes of one block of a grid object (block coordinates x, y, z), checked against their
  /// stored size and CRC-32; nullopt when the block has none. See grid_store.hpp.
  std::optional<SqlBlob> grid_block(ObjectId grid, const std::array<int32_t, 3>& key) const;
  std::vector<std::array<int32_t, 3>> grid_block_keys(ObjectId grid) const;
  /// Blocks and their total bytes [bytes].
  std::pair<size_t, size_t> grid_block_totals(ObjectId grid) const;

  // --- writing: each call is one transaction; write() groups several into one ---------------
  void write(const std::function<void()>& fn);
  /// Creates the folder and missing parents; returns the folder (existing ones are fine).
  ObjectId mkdir(const std::string& path);
  ObjectId add(ObjectId folder, const NewObject& object);
  /// A new version of `previous` (same folder and name), e.g. from reprocessing.
  ObjectId add_version(ObjectId previous, NewObject object);
  int64_t add_member(ObjectId multimesh, const MultiMeshMember& member);
  void set_member_transform(int64_t member_id, const Transform& T_parent_member);
  void set_metadata(ObjectId id, const nlohmann::json& metadata);
  /// Stores (inserts or replaces) one block of a grid object. Callers that write many blocks
  /// group them in one write() (the grid operations in grid_store.hpp do).
  void put_grid_block(ObjectId grid, const std::array<int32_t, 3>& key, const SqlBlob& data);
  /// Appends `input` to the provenance inputs of `id` (a grid that gained a mesh); throws when
  /// `id` has no provenance or `input` does not exist.
  void add_provenance_input(ObjectId id, ObjectId input);
  /// Refuses (naming them) when other objects were derived from `id` or a folder is not empty,
  /// unless `recursive`, which removes them too. Removes every version.
  void remove(ObjectId id, bool recursive);
  /// Into an existing folder (keeping the name), or to a new path whose folder exists.
  void move(ObjectId id, const std::string& destination);

  CheckReport check() const;
  const Database& database() const { return *db_; }
  /// See ChangeStamp: a long-running reader skips re-reading an unchanged workspace.
  ChangeStamp change_stamp() const { return {commits_, db_->others_version()}; }
  /// See Database::maintain_in_background: for a long-running writer that answers clients.
  void maintain_in_background() { db_->maintain_in_background(); }

 private:
  /// `folder_path`: the path of the row's folder when the caller knows it (saves the walk up).
  ObjectInfo row_to_info(const SqlRow& row, const std::string* folder_path = nullptr) const;
  std::string path_of(ObjectId id) const;
  void migrate();
  ObjectId insert_object(ObjectId folder, const NewObject& object, int64_t version, std::optional<ObjectId> previous);
  std::unique_ptr<Database> db_;
  int write_depth_ = 0;
  int64_t commits_ = 0;  ///< write() transactions committed
};

}  // namespace artisan::worldmodel
