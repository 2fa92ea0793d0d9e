#pragma once
// Private: the workspace schema, as migrations from an empty database. Migration i takes the
// schema from version i to version i + 1; never edit a released one, append a new one.
#include <string>
#include <vector>

namespace artisan::worldmodel::detail {

inline const std::vector<std::string>& migrations() {
  static const std::vector<std::string> all = {
      // 0 -> 1: the object tree, blobs, provenance, multimesh members.
      R"sql(
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE objects (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  kind TEXT NOT NULL CHECK (kind IN ('folder', 'image', 'mesh', 'multimesh', 'model', 'recognized_model', 'grid')),
  subkind TEXT NOT NULL DEFAULT '',
  folder_id INTEGER REFERENCES objects(id) DEFERRABLE INITIALLY DEFERRED,
  name TEXT NOT NULL,
  version INTEGER NOT NULL DEFAULT 1 CHECK (version >= 1),
  previous_version_id INTEGER REFERENCES objects(id) ON DELETE SET NULL,
  created_at TEXT NOT NULL,
  metadata TEXT NOT NULL DEFAULT '{}',
  UNIQUE (folder_id, name, version)
);
CREATE INDEX objects_by_folder ON objects (folder_id, name);
CREATE TABLE blobs (
  object_id INTEGER NOT NULL REFERENCES objects(id) ON DELETE CASCADE,
  role TEXT NOT NULL,
  encoding TEXT NOT NULL,
  size INTEGER NOT NULL,
  crc32 INTEGER NOT NULL,
  data BLOB NOT NULL,
  PRIMARY KEY (object_id, role)
);
CREATE TABLE provenance (
  object_id INTEGER PRIMARY KEY REFERENCES objects(id) ON DELETE CASCADE,
  operation TEXT NOT NULL,
  parameters TEXT NOT NULL,
  software TEXT NOT NULL
);
CREATE TABLE provenance_inputs (
  object_id INTEGER NOT NULL REFERENCES objects(id) ON DELETE CASCADE,
  position INTEGER NOT NULL,
  input_id INTEGER NOT NULL REFERENCES objects(id) DEFERRABLE INITIALLY DEFERRED,
  PRIMARY KEY (object_id, position)
);
CREATE INDEX provenance_inputs_by_input ON provenance_inputs (input_id);
CREATE TABLE multimesh_members (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  multimesh_id INTEGER NOT NULL REFERENCES objects(id) ON DELETE CASCADE,
  mesh_id INTEGER NOT NULL REFERENCES objects(id) DEFERRABLE INITIALLY DEFERRED,
  parent_member_id INTEGER REFERENCES multimesh_members(id) DEFERRABLE INITIALLY DEFERRED,
  T_parent_member TEXT NOT NULL,
  method TEXT NOT NULL,
  quality TEXT NOT NULL DEFAULT '{}'
);
CREATE INDEX multimesh_members_by_mesh ON multimesh_members (mesh_id);
)sql",
      // 1 -> 2: the blocks of grid objects (perception/integration), one row per block, sealed
      // with their size and CRC-32 like the blobs.
      R"sql(
CREATE TABLE grid_blocks (
  grid_id INTEGER NOT NULL REFERENCES objects(id) ON DELETE CASCADE,
  x INTEGER NOT NULL,
  y INTEGER NOT NULL,
  z INTEGER NOT NULL,
  size INTEGER NOT NULL,
  crc32 INTEGER NOT NULL,
  data BLOB NOT NULL,
  PRIMARY KEY (grid_id, x, y, z)
);
)sql",
      // 2 -> 3: robot objects (a URDF with its meshes, its pose and joint values). SQLite cannot
      // change a CHECK constraint in place: the objects table is rebuilt with every row and ID
      // (and its AUTOINCREMENT counter), with foreign keys off while it runs (see migrate()).
      R"sql(
CREATE TABLE objects_v3 (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  kind TEXT NOT NULL CHECK (kind IN ('folder', 'image', 'mesh', 'multimesh', 'model', 'recognized_model', 'grid', 'robot')),
  subkind TEXT NOT NULL DEFAULT '',
  folder_id INTEGER REFERENCES objects(id) DEFERRABLE INITIALLY DEFERRED,
  name TEXT NOT NULL,
  version INTEGER NOT NULL DEFAULT 1 CHECK (version >= 1),
  previous_version_id INTEGER REFERENCES objects(id) ON DELETE SET NULL,
  created_at TEXT NOT NULL,
  metadata TEXT NOT NULL DEFAULT '{}',
  UNIQUE (folder_id, name, version)
);
INSERT INTO objects_v3 (id, kind, subkind, folder_id, name, version, previous_version_id, created_at, metadata)
  SELECT id, kind, subkind, folder_id, name, version, previous_version_id, created_at, metadata FROM objects ORDER BY id;
UPDATE sqlite_sequence SET seq = (SELECT MAX(seq) FROM sqlite_sequence WHERE name IN ('objects', 'objects_v3')) WHERE name = 'objects_v3';
DROP TABLE objects;
ALTER TABLE objects_v3 RENAME TO objects;
CREATE INDEX objects_by_folder ON objects (folder_id, name);
)sql",
  };
  return all;
}

}  // namespace artisan::worldmodel::detail
