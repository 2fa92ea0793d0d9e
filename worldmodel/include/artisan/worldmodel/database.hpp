#pragma once
// The narrow SQL interface the workspace is written against. SQLite implements it today; a
// PostgreSQL backend (many operators, worker machines) implements the same class later, and
// no caller changes. Statements use "?" placeholders.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <variant>
#include <vector>

namespace artisan::worldmodel {

using SqlBlob = std::vector<uint8_t>;
using SqlValue = std::variant<std::nullptr_t, int64_t, double, std::string, SqlBlob>;
using SqlRow = std::vector<SqlValue>;

class Database {
 public:
  virtual ~Database() = default;
  /// Runs one statement with parameters; returns the rows it yields (none for writes).
  virtual std::vector<SqlRow> query(const std::string& sql, const std::vector<SqlValue>& params = {}) = 0;
  /// Runs one or more statements without parameters (schema scripts).
  virtual void execute_script(const std::string& sql) = 0;
  virtual int64_t last_insert_id() = 0;
  virtual bool has_table(const std::string& name) = 0;
  /// Starts a write transaction, waiting for other writers (busy timeout) rather than failing.
  virtual void begin_write() = 0;
  virtual void begin_read() = 0;
  virtual void commit() = 0;
  virtual void rollback() = 0;
  /// Backend-level integrity problems (corrupt pages, foreign-key violations); empty when sound.
  virtual std::vector<std::string> integrity_problems() = 0;
  virtual std::string description() const = 0;  ///< e.g. "sqlite:/path/to/artisan.db"
  /// A number that changes whenever another connection commits to the database (this
  /// connection's own commits leave it as it is). SQLite: PRAGMA data_version.
  virtual int64_t others_version() = 0;
  /// From now on, durable maintenance that a commit would otherwise do itself (SQLite: copying
  /// the write-ahead log into the database file, with its fsyncs) runs on a background thread,
  /// so that a writer that must answer within milliseconds (the world-model service) is not
  /// the one that waits for the disk. Backends without such work do nothing.
  virtual void maintain_in_background() {}
};

struct SqliteOptions {
  bool create = false;           ///< create the file when it does not exist
  int busy_timeout_ms = 30000;   ///< how long a writer waits for another [ms]
};

/// Opens an SQLite database in WAL mode with foreign keys on. Throws artisan::Error naming the
/// path when it cannot be opened or is not an SQLite file.
std::unique_ptr<Database> open_sqlite(const std::filesystem::path& path, const SqliteOptions& options = {});

/// Commits on commit(); rolls back if destroyed first (an exception, an early return).
class Transaction {
 public:
  enum class Mode { kRead, kWrite };
  Transaction(Database& db, Mode mode) : db_(db) {
    if (mode == Mode::kWrite) db_.begin_write();
    else db_.begin_read();
  }
  ~Transaction() {
    if (!done_) {
      try {
        db_.rollback();
      } catch (...) {
      }
    }
  }
  void commit() {
    db_.commit();
    done_ = true;
  }
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;

 private:
  Database& db_;
  bool done_ = false;
};

}  // namespace artisan::worldmodel
