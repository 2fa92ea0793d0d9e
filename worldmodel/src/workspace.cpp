#include "artisan/worldmodel/workspace.hpp"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <ctime>
#include <set>

#include "artisan/core/error.hpp"
#include "artisan/core/io/blob_container.hpp"
#include "artisan/core/io/mesh_format.hpp"
#include "artisan/core/io/range_image_format.hpp"
#include "schema.hpp"

namespace artisan::worldmodel {

namespace {

using nlohmann::json;

constexpr const char* kSoftware = "artisan 0.1.0";
constexpr const char* kRangeImageEncoding = "artisan-range-image/1";
constexpr const char* kMeshEncoding = "artisan-mesh/1";
constexpr const char* kObjectColumns =
    "id, kind, subkind, folder_id, name, version, previous_version_id, created_at, metadata";

int64_t as_int(const SqlValue& v) { return std::get<int64_t>(v); }
std::string as_text(const SqlValue& v) { return std::get<std::string>(v); }
std::optional<int64_t> as_optional_int(const SqlValue& v) {
  if (std::holds_alternative<std::nullptr_t>(v)) return std::nullopt;
  return std::get<int64_t>(v);
}
SqlValue optional_value(const std::optional<int64_t>& v) { return v ? SqlValue(*v) : SqlValue(nullptr); }

std::string now_utc() {
  const auto now = std::chrono::system_clock::now();
  const auto t = std::chrono::system_clock::to_time_t(now);
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[96];
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday,
                tm.tm_hour, tm.tm_min, tm.tm_sec, static_cast<int>(ms));
  return buf;
}

std::vector<std::string> split_path(const std::string& path) {
  std::vector<std::string> parts;
  size_t start = 1;
  while (start < path.size()) {
    const size_t end = path.find('/', start);
    parts.push_back(path.substr(start, end == std::string::npos ? std::string::npos : end - start));
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return parts;
}

json transform_json(const Transform& T) { return to_row_major(T); }

Transform transform_from_json(const json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 16) throw Error(what + ": not a row-major 4x4 array");
  std::array<double, 16> m{};
  for (size_t i = 0; i < 16; ++i) m[i] = j[i].get<double>();
  return from_row_major(m);
}

json image_metadata(const RangeImage& image) {
  json sensor = {{"kind", image.sensor.kind}, {"name", image.sensor.name}, {"timestamp_s", image.sensor.timestamp_s},
                 {"attributes", image.sensor.attributes}};
  if (image.sensor.T_world_sensor) sensor["T_world_sensor"] = transform_json(*image.sensor.T_world_sensor);
  json cameras = json::array();
  for (const auto& cam : image.images)
    cameras.push_back({{"name", cam.name}, {"width", cam.image.width}, {"height", cam.image.height}, {"channels", cam.image.channels}});
  return {{"width", image.width}, {"height", image.height}, {"valid_pixels", image.valid_count()}, {"sensor", sensor},
          {"camera_images", cameras}};
}

}  // namespace

NewObject make_image_object(const std::string& name, const RangeImage& image, const Provenance& provenance) {
  NewObject o;
  o.kind = ObjectKind::kImage;
  o.subkind = image.sensor.kind;
  o.name = name;
  o.metadata = image_metadata(image);
  o.blobs.push_back({"range_image", kRangeImageEncoding, io::encode_range_image(image)});
  o.provenance = provenance;
  return o;
}

NewObject make_mesh_object(ObjectKind kind, const std::string& subkind, const std::string& name, const TriangleMesh& mesh,
                           const Provenance& provenance, json metadata) {
  if (kind != ObjectKind::kMesh && kind != ObjectKind::kModel) throw Error("a mesh object must be a mesh or a model, not a " + to_string(kind));
  NewObject o;
  o.kind = kind;
  o.subkind = subkind;
  o.name = name;
  o.metadata = std::move(metadata);
  o.metadata["vertices"] = mesh.vertices.size();
  o.metadata["faces"] = mesh.faces.size();
  o.metadata["resolution_m"] = mesh.median_edge_length();
  o.blobs.push_back({"mesh", kMeshEncoding, io::encode_mesh(mesh)});
  o.provenance = provenance;
  return o;
}

std::string to_string(ObjectKind kind) {
  switch (kind) {
    case ObjectKind::kFolder: return "folder";
    case ObjectKind::kImage: return "image";
    case ObjectKind::kMesh: return "mesh";
    case ObjectKind::kMultiMesh: return "multimesh";
    case ObjectKind::kModel: return "model";
    case ObjectKind::kRecognizedModel: return "recognized_model";
    case ObjectKind::kGrid: return "grid";
    case ObjectKind::kRobot: return "robot";
  }
  return "?";
}

ObjectKind object_kind_from_string(const std::string& name) {
  for (auto k : {ObjectKind::kFolder, ObjectKind::kImage, ObjectKind::kMesh, ObjectKind::kMultiMesh, ObjectKind::kModel,
                 ObjectKind::kRecognizedModel, ObjectKind::kGrid, ObjectKind::kRobot})
    if (to_string(k) == name) return k;
  throw Error("unknown object kind \"" + name + "\" (folder, image, mesh, multimesh, model, recognized_model, grid, robot)");
}

void validate_name(const std::string& name) {
  if (name.empty()) throw Error("empty object name");
  if (name == "." || name == "..") throw Error("object name \"" + name + "\" is reserved");
  if (name.size() > 255) throw Error("object name \"" + name.substr(0, 40) + "...\" is longer than 255 characters");
  for (unsigned char c : name) {
    if (!(std::isalnum(c) || c == '.' || c == '_' || c == '-' || c == '+'))
      throw Error("object name \"" + name + "\" has the character '" + std::string(1, static_cast<char>(c)) +
                  "'; use letters, digits and . _ - +");
  }
}

void validate_path(const std::string& path) {
  if (path.empty() || path[0] != '/') throw Error("path \"" + path + "\" is not absolute (it must start with /)");
  if (path == "/") return;
  if (path.back() == '/') throw Error("path \"" + path + "\" ends with /");
  for (const auto& part : split_path(path)) {
    if (part.empty()) throw Error("path \"" + path + "\" has an empty component (//)");
    try {
      validate_name(part);
    } catch (const Error& e) {
      throw Error("path \"" + path + "\": " + e.what());
    }
  }
}

Workspace Workspace::create(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) throw Error("workspace " + path.string() + " already exists");
  return Workspace(open_sqlite(path, {.create = true}));
}

Workspace Workspace::open(const std::filesystem::path& path) { return Workspace(open_sqlite(path, {.create = false})); }

Workspace::Workspace(std::unique_ptr<Database> db) : db_(std::move(db)) { migrate(); }
Workspace::Workspace(Workspace&&) noexcept = default;
Workspace& Workspace::operator=(Workspace&&) noexcept = default;
Workspace::~Workspace() = default;

void Workspace::migrate() {
  const auto& steps = detail::migrations();
  static_assert(kSchemaVersion >= 1);
  assert(steps.size() == static_cast<size_t>(kSchemaVersion));
  int version = 0;
  if (db_->has_table("meta")) {
    version = schema_version();
  } else if (db_->has_table("objects")) {
    throw Error(db_->description() + " is not an Artisan workspace (it has tables but no schema version)");
  }
  if (version > kSchemaVersion)
    throw Error(db_->description() + " has schema version " + std::to_string(version) + ", newer than this build's " +
                std::to_string(kSchemaVersion) + "; update Artisan");
  if (version == kSchemaVersion) return;
  // A migration that rebuilds a table (SQLite's way to change a constraint) must not cascade the
  // old table's deletion into the tables that reference it: foreign keys are off while the
  // migrations run (this can only change outside a transaction), checked before the commit, and
  // on again afterwards.
  db_->execute_script("PRAGMA foreign_keys=OFF");
  struct ForeignKeysOn {
    Database& db;
    ~ForeignKeysOn() {
      try {
        db.execute_script("PRAGMA foreign_keys=ON");
      } catch (...) {
      }
    }
  } foreign_keys_on{*db_};
  write([&] {
    // Another process may have migrated while we waited for the write lock.
    int current = db_->has_table("meta") ? schema_version() : 0;
    for (; current < kSchemaVersion; ++current) db_->execute_script(steps[current]);
    if (const auto broken = db_->query("PRAGMA foreign_key_check"); !broken.empty())
      throw Error(db_->description() + ": migrating to schema version " + std::to_string(kSchemaVersion) + " would break " +
                  std::to_string(broken.size()) + " reference(s); the workspace is left as it was");
    db_->query("INSERT OR REPLACE INTO meta (key, value) VALUES ('schema_version', ?)", {std::to_string(kSchemaVersion)});
    if (db_->query("SELECT id FROM objects WHERE folder_id IS NULL").empty()) {
      db_->query("INSERT INTO objects (kind, name, created_at) VALUES ('folder', '', ?)", {now_utc()});
    }
  });
}

int Workspace::schema_version() const {
  const auto rows = db_->query("SELECT value FROM meta WHERE key = 'schema_version'");
  if (rows.empty()) throw Error(db_->description() + " has no schema version");
  return std::stoi(as_text(rows[0][0]));
}

void Workspace::write(const std::function<void()>& fn) {
  if (write_depth_ > 0) {
    fn();
    return;
  }
  Transaction tx(*db_, Transaction::Mode::kWrite);
  ++write_depth_;
  try {
    fn();
  } catch (...) {
    --write_depth_;
    throw;
  }
  --write_depth_;
  tx.commit();
  ++commits_;
}

ObjectId Workspace::root() const {
  const auto rows = db_->query("SELECT id FROM objects WHERE folder_id IS NULL AND kind = 'folder'");
  if (rows.size() != 1) throw Error(db_->description() + ": the workspace has " + std::to_string(rows.size()) + " root folders");
  return as_int(rows[0][0]);
}

ObjectInfo Workspace::row_to_info(const SqlRow& row, const std::string* folder_path) const {
  ObjectInfo info;
  info.id = as_int(row[0]);
  info.kind = object_kind_from_string(as_text(row[1]));
  info.subkind = as_text(row[2]);
  info.folder = as_optional_int(row[3]);
  info.name = as_text(row[4]);
  info.version = static_cast<int>(as_int(row[5]));
  info.previous_version = as_optional_int(row[6]);
  info.created_at = as_text(row[7]);
  info.metadata = json::parse(as_text(row[8]), nullptr, false);
  if (info.metadata.is_discarded()) throw Error("object " + std::to_string(info.id) + " has corrupt metadata");
  info.path = folder_path && info.folder ? (*folder_path == "/" ? "/" : *folder_path + "/") + info.name : path_of(info.id);
  return info;
}

std::string Workspace::path_of(ObjectId id) const {
  std::vector<std::string> parts;
  std::optional<ObjectId> cur = id;
  std::set<ObjectId> seen;
  while (cur) {
    if (!seen.insert(*cur).second) throw Error("object " + std::to_string(id) + ": its folders form a cycle");
    const auto rows = db_->query("SELECT folder_id, name FROM objects WHERE id = ?", {*cur});
    if (rows.empty()) throw Error("object " + std::to_string(*cur) + " does not exist");
    cur = as_optional_int(rows[0][0]);
    if (cur) parts.push_back(as_text(rows[0][1]));
  }
  std::string path;
  for (auto it = parts.rbegin(); it != parts.rend(); ++it) path += "/" + *it;
  return path.empty() ? "/" : path;
}

ObjectInfo Workspace::get(ObjectId id) const {
  const auto rows = db_->query(std::string("SELECT ") + kObjectColumns + " FROM objects WHERE id = ?", {id});
  if (rows.empty()) throw Error("no object with ID " + std::to_string(id));
  return row_to_info(rows[0]);
}

ObjectInfo Workspace::resolve(const std::string& id_or_path) const {
  if (id_or_path.empty()) throw Error("empty object ID or path");
  if (std::all_of(id_or_path.begin(), id_or_path.end(), [](unsigned char c) { return std::isdigit(c); })) {
    if (id_or_path.size() > 18) throw Error("no object with ID " + id_or_path);
    return get(std::stoll(id_or_path));
  }
  std::string path = id_or_path;
  std::optional<int> version;
  if (const auto at = path.rfind('@'); at != std::string::npos) {
    const auto v = path.substr(at + 1);
    if (v.empty() || v.size() > 9 || !std::all_of(v.begin(), v.end(), [](unsigned char c) { return std::isdigit(c); }))
      throw Error("\"" + id_or_path + "\": the version after @ must be a number");
    version = std::stoi(v);
    path = path.substr(0, at);
  }
  if (path.empty() || path[0] != '/')
    throw Error("\"" + id_or_path + "\" is neither an object ID (a number) nor a path (starting with /)");
  validate_path(path);
  ObjectId cur = root();
  const auto parts = split_path(path);
  for (size_t i = 0; i < parts.size(); ++i) {
    const bool last = i + 1 == parts.size();
    const auto rows = (last && version)
                          ? db_->query("SELECT id, kind FROM objects WHERE folder_id = ? AND name = ? AND version = ?",
                                       {cur, parts[i], static_cast<int64_t>(*version)})
                          : db_->query("SELECT id, kind FROM objects WHERE folder_id = ? AND name = ? ORDER BY version DESC LIMIT 1",
                                       {cur, parts[i]});
    if (rows.empty()) {
      std::string so_far;
      for (size_t k = 0; k <= i; ++k) so_far += "/" + parts[k];
      throw Error("no object at " + so_far + (last && version ? " with version " + std::to_string(*version) : ""));
    }
    if (!last && as_text(rows[0][1]) != "folder") throw Error("\"" + path + "\": " + parts[i] + " is not a folder");
    cur = as_int(rows[0][0]);
  }
  return get(cur);
}

ObjectInfo Workspace::folder(const std::string& path) const {
  auto info = resolve(path);
  if (info.kind != ObjectKind::kFolder) throw Error(path + " is a " + to_string(info.kind) + ", not a folder");
  return info;
}

std::vector<ObjectInfo> Workspace::children(ObjectId folder) const {
  const auto rows = db_->query(std::string("SELECT ") + kObjectColumns +
                                   " FROM objects o WHERE folder_id = ? AND version = (SELECT MAX(version) FROM objects v "
                                   "WHERE v.folder_id = o.folder_id AND v.name = o.name) "
                                   "ORDER BY kind != 'folder', name",
                               {folder});
  std::vector<ObjectInfo> out;
  if (rows.empty()) return out;
  const std::string folder_path = path_of(folder);
  for (const auto& r : rows) out.push_back(row_to_info(r, &folder_path));
  return out;
}

std::vector<ObjectInfo> Workspace::versions(ObjectId id) const {
  const auto info = get(id);
  if (!info.folder) return {info};
  const std::string folder_path = path_of(*info.folder);
  std::vector<ObjectInfo> out;
  for (const auto& r : db_->query(std::string("SELECT ") + kObjectColumns + " FROM objects WHERE folder_id = ? AND name = ? ORDER BY version",
                                  {*info.folder, info.name}))
    out.push_back(row_to_info(r, &folder_path));
  return out;
}

std::optional<Provenance> Workspace::provenance(ObjectId id) const {
  const auto rows = db_->query("SELECT operation, parameters FROM provenance WHERE object_id = ?", {id});
  if (rows.empty()) return std::nullopt;
  Provenance p;
  p.operation = as_text(rows[0][0]);
  p.parameters = json::parse(as_text(rows[0][1]), nullptr, false);
  if (p.parameters.is_discarded()) throw Error("object " + std::to_string(id) + " has corrupt provenance parameters");
  for (const auto& r : db_->query("SELECT input_id FROM provenance_inputs WHERE object_id = ? ORDER BY position", {id}))
    p.inputs.push_back(as_int(r[0]));
  return p;
}

std::vector<ObjectInfo> Workspace::derived_from(ObjectId id) const {
  std::vector<ObjectInfo> out;
  for (const auto& r : db_->query("SELECT DISTINCT object_id FROM provenance_inputs WHERE input_id = ? "
                                  "UNION SELECT multimesh_id FROM multimesh_members WHERE mesh_id = ? ORDER BY 1",
                                  {id, id}))
    out.push_back(get(as_int(r[0])));
  return out;
}

std::vector<ObjectBlob> Workspace::blobs(ObjectId id) const {
  std::vector<ObjectBlob> out;
  for (auto& r : db_->query("SELECT role, encoding, data FROM blobs WHERE object_id = ? ORDER BY role", {id}))
    out.push_back({as_text(r[0]), as_text(r[1]), std::move(std::get<SqlBlob>(r[2]))});
  return out;
}

SqlBlob Workspace::blob(ObjectId id, const std::string& role) const {
  auto rows = db_->query("SELECT data FROM blobs WHERE object_id = ? AND role = ?", {id, role});
  if (rows.empty()) throw Error(path_of(id) + " (ID " + std::to_string(id) + ") has no " + role + " data");
  return std::move(std::get<SqlBlob>(rows[0][0]));
}

RangeImage Workspace::load_image(ObjectId id) const {
  const auto info = get(id);
  if (info.kind != ObjectKind::kImage) throw Error(info.path + " (ID " + std::to_string(id) + ") is a " + to_string(info.kind) + ", not an image");
  return io::decode_range_image(blob(id, "range_image"), info.path + " (ID " + std::to_string(id) + ")");
}

TriangleMesh Workspace::load_mesh(ObjectId id) const {
  const auto info = get(id);
  if (info.kind != ObjectKind::kMesh && info.kind != ObjectKind::kModel)
    throw Error(info.path + " (ID " + std::to_string(id) + ") is a " + to_string(info.kind) + ", not a mesh");
  return io::decode_mesh(blob(id, "mesh"), info.path + " (ID " + std::to_string(id) + ")");
}

std::vector<MultiMeshMember> Workspace::members(ObjectId multimesh) const {
  std::vector<MultiMeshMember> out;
  for (const auto& r : db_->query("SELECT id, mesh_id, parent_member_id, T_parent_member, method, quality FROM multimesh_members "
                                  "WHERE multimesh_id = ? ORDER BY id",
                                  {multimesh})) {
    MultiMeshMember m;
    m.member_id = as_int(r[0]);
    m.mesh = as_int(r[1]);
    m.parent_member = as_optional_int(r[2]);
    m.T_parent_member = transform_from_json(json::parse(as_text(r[3])), "member " + std::to_string(m.member_id));
    m.method = as_text(r[4]);
    m.quality = json::parse(as_text(r[5]));
    out.push_back(std::move(m));
  }
  return out;
}

std::optional<SqlBlob> Workspace::grid_block(ObjectId grid, const std::array<int32_t, 3>& key) const {
  auto rows = db_->query("SELECT size, crc32, data FROM grid_blocks WHERE grid_id = ? AND x = ? AND y = ? AND z = ?",
                         {grid, int64_t{key[0]}, int64_t{key[1]}, int64_t{key[2]}});
  if (rows.empty()) return std::nullopt;
  auto data = std::move(std::get<SqlBlob>(rows[0][2]));
  if (static_cast<int64_t>(data.size()) != as_int(rows[0][0]) || io::crc32_of(data) != static_cast<uint32_t>(as_int(rows[0][1])))
    throw Error(path_of(grid) + " (ID " + std::to_string(grid) + "): grid block (" + std::to_string(key[0]) + ", " +
                std::to_string(key[1]) + ", " + std::to_string(key[2]) + ") fails its size or checksum check");
  return data;
}

std::vector<std::array<int32_t, 3>> Workspace::grid_block_keys(ObjectId grid) const {
  std::vector<std::array<int32_t, 3>> out;
  for (const auto& r : db_->query("SELECT x, y, z FROM grid_blocks WHERE grid_id = ? ORDER BY x, y, z", {grid}))
    out.push_back({static_cast<int32_t>(as_int(r[0])), static_cast<int32_t>(as_int(r[1])), static_cast<int32_t>(as_int(r[2]))});
  return out;
}

std::pair<size_t, size_t> Workspace::grid_block_totals(ObjectId grid) const {
  const auto rows = db_->query("SELECT COUNT(*), COALESCE(SUM(size), 0) FROM grid_blocks WHERE grid_id = ?", {grid});
  return {static_cast<size_t>(as_int(rows[0][0])), static_cast<size_t>(as_int(rows[0][1]))};
}

void Workspace::put_grid_block(ObjectId grid, const std::array<int32_t, 3>& key, const SqlBlob& data) {
  write([&] {
    db_->query("INSERT OR REPLACE INTO grid_blocks (grid_id, x, y, z, size, crc32, data) VALUES (?, ?, ?, ?, ?, ?, ?)",
               {grid, int64_t{key[0]}, int64_t{key[1]}, int64_t{key[2]}, static_cast<int64_t>(data.size()),
                static_cast<int64_t>(io::crc32_of(data)), data});
  });
}

void Workspace::add_provenance_input(ObjectId id, ObjectId input) {
  write([&] {
    if (db_->query("SELECT 1 FROM provenance WHERE object_id = ?", {id}).empty())
      throw Error(path_of(id) + " (ID " + std::to_string(id) + ") has no provenance to add an input to");
    get(input);
    const auto rows = db_->query("SELECT COALESCE(MAX(position) + 1, 0) FROM provenance_inputs WHERE object_id = ?", {id});
    db_->query("INSERT INTO provenance_inputs (object_id, position, input_id) VALUES (?, ?, ?)", {id, as_int(rows[0][0]), input});
  });
}

ObjectId Workspace::mkdir(const std::string& path) {
  validate_path(path);
  ObjectId cur = root();
  write([&] {
    cur = root();
    for (const auto& part : split_path(path)) {
      const auto rows = db_->query("SELECT id, kind FROM objects WHERE folder_id = ? AND name = ? ORDER BY version DESC LIMIT 1", {cur, part});
      if (!rows.empty()) {
        if (as_text(rows[0][1]) != "folder") throw Error("cannot make folder " + path + ": " + path_of(as_int(rows[0][0])) + " is a " + as_text(rows[0][1]));
        cur = as_int(rows[0][0]);
        continue;
      }
      NewObject f;
      f.kind = ObjectKind::kFolder;
      f.name = part;
      cur = add(cur, f);
    }
  });
  return cur;
}

ObjectId Workspace::insert_object(ObjectId folder, const NewObject& object, int64_t version, std::optional<ObjectId> previous) {
  db_->query("INSERT INTO objects (kind, subkind, folder_id, name, version, previous_version_id, created_at, metadata) "
             "VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
             {to_string(object.kind), object.subkind, folder, object.name, version, optional_value(previous), now_utc(),
              object.metadata.dump()});
  const ObjectId id = db_->last_insert_id();
  for (const auto& b : object.blobs)
    db_->query("INSERT INTO blobs (object_id, role, encoding, size, crc32, data) VALUES (?, ?, ?, ?, ?, ?)",
               {id, b.role, b.encoding, static_cast<int64_t>(b.data.size()), static_cast<int64_t>(io::crc32_of(b.data)), b.data});
  if (object.provenance) {
    db_->query("INSERT INTO provenance (object_id, operation, parameters, software) VALUES (?, ?, ?, ?)",
               {id, object.provenance->operation, object.provenance->parameters.dump(), std::string(kSoftware)});
    int64_t position = 0;
    for (ObjectId input : object.provenance->inputs) {
      if (db_->query("SELECT 1 FROM objects WHERE id = ?", {input}).empty())
        throw Error("input object " + std::to_string(input) + " does not exist");
      db_->query("INSERT INTO provenance_inputs (object_id, position, input_id) VALUES (?, ?, ?)", {id, position++, input});
    }
  }
  return id;
}

ObjectId Workspace::add(ObjectId folder, const NewObject& object) {
  validate_name(object.name);
  ObjectId id = 0;
  write([&] {
    const auto parent = get(folder);
    if (parent.kind != ObjectKind::kFolder) throw Error(parent.path + " is a " + to_string(parent.kind) + ", not a folder");
    const auto existing = db_->query("SELECT id FROM objects WHERE folder_id = ? AND name = ? LIMIT 1", {folder, object.name});
    if (!existing.empty())
      throw Error(path_of(as_int(existing[0][0])) + " already exists (ID " + std::to_string(as_int(existing[0][0])) + ")");
    id = insert_object(folder, object, 1, std::nullopt);
  });
  return id;
}

ObjectId Workspace::add_version(ObjectId previous, NewObject object) {
  ObjectId id = 0;
  write([&] {
    const auto prev = get(previous);
    if (!prev.folder) throw Error("the root folder has no versions");
    const auto rows = db_->query("SELECT MAX(version) FROM objects WHERE folder_id = ? AND name = ?", {*prev.folder, prev.name});
    const int64_t version = as_int(rows[0][0]) + 1;
    object.name = prev.name;
    id = insert_object(*prev.folder, object, version, previous);
  });
  return id;
}

int64_t Workspace::add_member(ObjectId multimesh, const MultiMeshMember& member) {
  int64_t id = 0;
  write([&] {
    if (get(multimesh).kind != ObjectKind::kMultiMesh) throw Error(path_of(multimesh) + " is not a multimesh");
    if (get(member.mesh).kind != ObjectKind::kMesh) throw Error(path_of(member.mesh) + " is not a mesh");
    db_->query("INSERT INTO multimesh_members (multimesh_id, mesh_id, parent_member_id, T_parent_member, method, quality) VALUES (?, ?, ?, ?, ?, ?)",
               {multimesh, member.mesh, optional_value(member.parent_member), transform_json(member.T_parent_member).dump(), member.method,
                member.quality.dump()});
    id = db_->last_insert_id();
  });
  return id;
}

void Workspace::set_member_transform(int64_t member_id, const Transform& T_parent_member) {
  write([&] {
    if (db_->query("SELECT 1 FROM multimesh_members WHERE id = ?", {member_id}).empty())
      throw Error("no multimesh member " + std::to_string(member_id));
    db_->query("UPDATE multimesh_members SET T_parent_member = ? WHERE id = ?", {transform_json(T_parent_member).dump(), member_id});
  });
}

void Workspace::set_metadata(ObjectId id, const json& metadata) {
  write([&] {
    get(id);
    db_->query("UPDATE objects SET metadata = ? WHERE id = ?", {metadata.dump(), id});
  });
}

void Workspace::remove(ObjectId id, bool recursive) {
  write([&] {
    const auto target = get(id);
    if (!target.folder) throw Error("the root folder cannot be removed");
    // Everything that goes with the target: its versions, a folder's contents, and whatever
    // was derived from any of them, transitively.
    std::set<ObjectId> doomed;
    std::vector<ObjectId> todo;
    for (const auto& v : versions(id)) todo.push_back(v.id);
    std::set<ObjectId> own(todo.begin(), todo.end());
    while (!todo.empty()) {
      const ObjectId cur = todo.back();
      todo.pop_back();
      if (!doomed.insert(cur).second) continue;
      for (const auto& r : db_->query("SELECT id FROM objects WHERE folder_id = ?", {cur})) todo.push_back(as_int(r[0]));
      for (const auto& d : derived_from(cur)) todo.push_back(d.id);
    }
    if (!recursive && doomed.size() > own.size()) {
      std::string names;
      size_t shown = 0;
      for (ObjectId d : doomed) {
        if (own.count(d)) continue;
        if (shown++ < 8) names += "\n  " + path_of(d) + " (ID " + std::to_string(d) + ")";
      }
      if (shown > 8) names += "\n  ... and " + std::to_string(shown - 8) + " more";
      throw Error("cannot remove " + target.path + ": " + std::to_string(shown) +
                  (target.kind == ObjectKind::kFolder ? " objects are inside it or derived from it:" : " objects were derived from it:") +
                  names + "\n(use --recursive to remove them too)");
    }
    for (ObjectId d : doomed) {
      db_->query("DELETE FROM multimesh_members WHERE mesh_id = ?", {d});
      db_->query("DELETE FROM objects WHERE id = ?", {d});
    }
  });
}

void Workspace::move(ObjectId id, const std::string& destination) {
  write([&] {
    const auto target = get(id);
    if (!target.folder) throw Error("the root folder cannot be moved");
    validate_path(destination);
    ObjectId new_folder = 0;
    std::string new_name = target.name;
    ObjectInfo dest_info;
    bool dest_exists = true;
    try {
      dest_info = resolve(destination);
    } catch (const Error&) {
      dest_exists = false;
    }
    if (dest_exists && dest_info.kind == ObjectKind::kFolder) {
      new_folder = dest_info.id;
    } else if (dest_exists) {
      throw Error("cannot move " + target.path + " to " + destination + ": it already exists (ID " + std::to_string(dest_info.id) + ")");
    } else {
      const auto slash = destination.rfind('/');
      new_folder = folder(slash == 0 ? "/" : destination.substr(0, slash)).id;
      new_name = destination.substr(slash + 1);
    }
    // A folder cannot go inside itself.
    for (std::optional<ObjectId> cur = new_folder; cur; cur = get(*cur).folder)
      if (*cur == id) throw Error("cannot move " + target.path + " into itself (" + destination + ")");
    if (!db_->query("SELECT id FROM objects WHERE folder_id = ? AND name = ? AND NOT (folder_id = ? AND name = ?)",
                    {new_folder, new_name, *target.folder, target.name})
             .empty())
      throw Error("cannot move " + target.path + ": " + path_of(new_folder) + " already holds \"" + new_name + "\"");
    db_->query("UPDATE objects SET folder_id = ?, name = ? WHERE folder_id = ? AND name = ?",
               {new_folder, new_name, *target.folder, target.name});
  });
}

CheckReport Workspace::check() const {
  CheckReport report;
  report.problems = db_->integrity_problems();
  try {
    report.schema_version = schema_version();
    if (report.schema_version != kSchemaVersion)
      report.problems.push_back("schema version " + std::to_string(report.schema_version) + ", expected " + std::to_string(kSchemaVersion));
  } catch (const Error& e) {
    report.problems.push_back(e.what());
  }
  report.objects = static_cast<size_t>(as_int(db_->query("SELECT COUNT(*) FROM objects")[0][0]));
  const auto roots = db_->query("SELECT COUNT(*) FROM objects WHERE folder_id IS NULL")[0][0];
  if (as_int(roots) != 1) report.problems.push_back(std::to_string(as_int(roots)) + " root folders (expected 1)");
  for (const auto& r : db_->query("SELECT o.id, o.name, o.folder_id FROM objects o LEFT JOIN objects f ON f.id = o.folder_id "
                                  "WHERE o.folder_id IS NOT NULL AND (f.id IS NULL OR f.kind != 'folder')"))
    report.problems.push_back("object " + std::to_string(as_int(r[0])) + " (" + as_text(r[1]) + ") is in " +
                              std::to_string(as_int(r[2])) + ", which is not a folder");
  for (const auto& r : db_->query("SELECT p.object_id, p.input_id FROM provenance_inputs p LEFT JOIN objects o ON o.id = p.input_id WHERE o.id IS NULL"))
    report.problems.push_back("object " + std::to_string(as_int(r[0])) + " was derived from missing object " + std::to_string(as_int(r[1])));
  for (const auto& r : db_->query("SELECT id, metadata FROM objects")) {
    if (json::parse(as_text(r[1]), nullptr, false).is_discarded())
      report.problems.push_back("object " + std::to_string(as_int(r[0])) + " has corrupt metadata");
  }
  for (const auto& r : db_->query("SELECT object_id, role, encoding, size, crc32, data FROM blobs")) {
    ++report.blobs;
    const auto& data = std::get<SqlBlob>(r[5]);
    const std::string where = "object " + std::to_string(as_int(r[0])) + " " + as_text(r[1]) + " data";
    if (static_cast<int64_t>(data.size()) != as_int(r[3]) || io::crc32_of(data) != static_cast<uint32_t>(as_int(r[4]))) {
      report.problems.push_back(where + ": checksum or size mismatch");
      continue;
    }
    try {
      const auto encoding = as_text(r[2]);
      if (encoding == kRangeImageEncoding) io::decode_range_image(data, where);
      else if (encoding == kMeshEncoding) io::decode_mesh(data, where);
    } catch (const Error& e) {
      report.problems.push_back(e.what());
    }
  }
  for (const auto& r : db_->query("SELECT b.grid_id, b.x, b.y, b.z, b.size, b.crc32, b.data, o.kind FROM grid_blocks b "
                                  "LEFT JOIN objects o ON o.id = b.grid_id")) {
    ++report.blobs;
    const auto& data = std::get<SqlBlob>(r[6]);
    const std::string where = "object " + std::to_string(as_int(r[0])) + " grid block (" + std::to_string(as_int(r[1])) + ", " +
                              std::to_string(as_int(r[2])) + ", " + std::to_string(as_int(r[3])) + ")";
    if (!std::holds_alternative<std::string>(r[7]) || as_text(r[7]) != "grid")
      report.problems.push_back(where + ": the object is not a grid");
    if (static_cast<int64_t>(data.size()) != as_int(r[4]) || io::crc32_of(data) != static_cast<uint32_t>(as_int(r[5])))
      report.problems.push_back(where + ": checksum or size mismatch");
  }
  return report;
}

}  // namespace artisan::worldmodel
