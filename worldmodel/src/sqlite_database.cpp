#include <sqlite3.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <unordered_map>

#include "artisan/core/error.hpp"
#include "artisan/core/scheduling.hpp"
#include "artisan/worldmodel/database.hpp"

namespace artisan::worldmodel {

namespace {

class SqliteDatabase final : public Database {
 public:
  SqliteDatabase(const std::filesystem::path& path, const SqliteOptions& options) : path_(path) {
    std::error_code ec;
    if (!options.create && !std::filesystem::exists(path, ec))
      throw Error("workspace " + path.string() + " does not exist (create it with: artisan --db " + path.string() + " init)");
    const int flags = SQLITE_OPEN_READWRITE | (options.create ? SQLITE_OPEN_CREATE : 0) | SQLITE_OPEN_NOMUTEX;
    if (sqlite3_open_v2(path.c_str(), &db_, flags, nullptr) != SQLITE_OK) {
      const std::string why = db_ ? sqlite3_errmsg(db_) : "out of memory";
      sqlite3_close(db_);
      throw Error("workspace " + path.string() + ": cannot open: " + why);
    }
    sqlite3_busy_timeout(db_, options.busy_timeout_ms);
    sqlite3_extended_result_codes(db_, 1);
    try {
      // Reading the schema fails here when the file is not an SQLite database.
      query("PRAGMA journal_mode=WAL", {});
      execute_script("PRAGMA foreign_keys=ON; PRAGMA synchronous=NORMAL;");
    } catch (const Error& e) {
      sqlite3_close(db_);
      throw Error("workspace " + path.string() + " is not an Artisan workspace: " + e.what());
    }
  }
  ~SqliteDatabase() override {
    if (checkpointer_.joinable()) {
      {
        std::lock_guard lock(checkpoint_mutex_);
        stop_ = true;
      }
      checkpoint_wanted_.notify_one();
      checkpointer_.join();
    }
    for (auto& [sql, stmt] : statements_) sqlite3_finalize(stmt);
    sqlite3_close(db_);
  }

  std::vector<SqlRow> query(const std::string& sql, const std::vector<SqlValue>& params) override {
    // Statements are prepared once and kept (the workspace asks the same few questions again
    // and again; preparing costs more than most of them take to answer). A statement runs to
    // its end before query() returns, so no two uses of one statement overlap.
    sqlite3_stmt* stmt = nullptr;
    if (auto it = statements_.find(sql); it != statements_.end()) {
      stmt = it->second;
    } else {
      check(sqlite3_prepare_v3(db_, sql.c_str(), static_cast<int>(sql.size()), SQLITE_PREPARE_PERSISTENT, &stmt, nullptr), sql);
      if (statements_.size() >= kMaxStatements) {
        for (auto& [old_sql, old] : statements_) sqlite3_finalize(old);
        statements_.clear();
      }
      statements_.emplace(sql, stmt);
    }
    struct Reset {
      sqlite3_stmt* s;
      ~Reset() {
        sqlite3_reset(s);
        sqlite3_clear_bindings(s);
      }
    } reset{stmt};
    for (size_t i = 0; i < params.size(); ++i) {
      const int k = static_cast<int>(i + 1);
      const auto& p = params[i];
      int rc = SQLITE_OK;
      if (std::holds_alternative<std::nullptr_t>(p)) rc = sqlite3_bind_null(stmt, k);
      else if (const auto* v = std::get_if<int64_t>(&p)) rc = sqlite3_bind_int64(stmt, k, *v);
      else if (const auto* d = std::get_if<double>(&p)) rc = sqlite3_bind_double(stmt, k, *d);
      else if (const auto* s = std::get_if<std::string>(&p)) rc = sqlite3_bind_text64(stmt, k, s->data(), s->size(), SQLITE_TRANSIENT, SQLITE_UTF8);
      else {
        const auto& b = std::get<SqlBlob>(p);
        rc = sqlite3_bind_blob64(stmt, k, b.empty() ? "" : static_cast<const void*>(b.data()), b.size(), SQLITE_TRANSIENT);
      }
      check(rc, sql);
    }
    std::vector<SqlRow> rows;
    while (true) {
      const int rc = sqlite3_step(stmt);
      if (rc == SQLITE_DONE) break;
      if (rc != SQLITE_ROW) check(rc, sql);
      SqlRow row(sqlite3_column_count(stmt));
      for (int c = 0; c < static_cast<int>(row.size()); ++c) {
        switch (sqlite3_column_type(stmt, c)) {
          case SQLITE_INTEGER: row[c] = static_cast<int64_t>(sqlite3_column_int64(stmt, c)); break;
          case SQLITE_FLOAT: row[c] = sqlite3_column_double(stmt, c); break;
          case SQLITE_TEXT:
            row[c] = std::string(reinterpret_cast<const char*>(sqlite3_column_text(stmt, c)), sqlite3_column_bytes(stmt, c));
            break;
          case SQLITE_BLOB: {
            const auto* data = static_cast<const uint8_t*>(sqlite3_column_blob(stmt, c));
            row[c] = SqlBlob(data, data + sqlite3_column_bytes(stmt, c));
            break;
          }
          default: row[c] = nullptr;
        }
      }
      rows.push_back(std::move(row));
    }
    return rows;
  }

  void execute_script(const std::string& sql) override {
    char* err = nullptr;
    if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
      const std::string why = err ? err : sqlite3_errmsg(db_);
      sqlite3_free(err);
      throw Error("workspace " + path_.string() + ": " + why);
    }
  }

  int64_t last_insert_id() override { return sqlite3_last_insert_rowid(db_); }
  bool has_table(const std::string& name) override {
    return !query("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", {name}).empty();
  }
  // BEGIN IMMEDIATE takes the write lock up front, so the busy timeout applies to it and two
  // writers never deadlock upgrading read locks.
  void begin_write() override { execute_script("BEGIN IMMEDIATE"); }
  void begin_read() override { execute_script("BEGIN"); }
  void commit() override { execute_script("COMMIT"); }
  void rollback() override { execute_script("ROLLBACK"); }

  std::vector<std::string> integrity_problems() override {
    std::vector<std::string> problems;
    for (const auto& row : query("PRAGMA integrity_check", {})) {
      const auto& s = std::get<std::string>(row[0]);
      if (s != "ok") problems.push_back("sqlite integrity: " + s);
    }
    for (const auto& row : query("PRAGMA foreign_key_check", {})) {
      problems.push_back("foreign key violation in table " + std::get<std::string>(row[0]) + " row " +
                         (std::holds_alternative<int64_t>(row[1]) ? std::to_string(std::get<int64_t>(row[1])) : "?") +
                         " (refers to " + std::get<std::string>(row[2]) + ")");
    }
    return problems;
  }

  std::string description() const override { return "sqlite:" + path_.string(); }
  int64_t others_version() override { return std::get<int64_t>(query("PRAGMA data_version", {}).at(0).at(0)); }

  // SQLite's own checkpoint runs inside the commit that fills the log past 1000 pages, and
  // fsyncs the log and the database: milliseconds, up to tens of them on a busy disk, in the
  // middle of an edit. Here the commit only signals (the WAL hook replaces the automatic
  // checkpoint), and a thread with a connection of its own makes a passive checkpoint, which
  // never blocks the writer: it copies what no reader still needs, and the next one does the rest.
  void maintain_in_background() override {
    if (checkpointer_.joinable()) return;
    sqlite3* own = nullptr;
    // A connection that has read nothing yet does not know the file is in WAL mode, and its
    // checkpoints do nothing: the pragma opens the log.
    if (sqlite3_open_v2(path_.c_str(), &own, SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX, nullptr) != SQLITE_OK ||
        sqlite3_exec(own, "PRAGMA journal_mode=WAL", nullptr, nullptr, nullptr) != SQLITE_OK) {
      const std::string why = own ? sqlite3_errmsg(own) : "out of memory";
      sqlite3_close(own);
      throw Error("workspace " + path_.string() + ": cannot open a connection for background checkpoints: " + why);
    }
    sqlite3_busy_timeout(own, 1000);
    sqlite3_wal_hook(
        db_,
        [](void* self, sqlite3*, const char*, int pages) {
          auto& me = *static_cast<SqliteDatabase*>(self);
          if (pages >= kCheckpointPages) {
            std::lock_guard lock(me.checkpoint_mutex_);
            me.checkpoint_due_ = true;
            me.checkpoint_wanted_.notify_one();
          }
          return SQLITE_OK;
        },
        this);
    checkpointer_ = std::thread([this, own] {
      run_in_background();
      std::unique_lock lock(checkpoint_mutex_);
      while (true) {
        checkpoint_wanted_.wait(lock, [&] { return stop_ || checkpoint_due_; });
        if (stop_) break;
        checkpoint_due_ = false;
        lock.unlock();
        // Busy or not complete (a reader on an old snapshot): the next commit asks again.
        sqlite3_wal_checkpoint_v2(own, nullptr, SQLITE_CHECKPOINT_PASSIVE, nullptr, nullptr);
        lock.lock();
      }
      sqlite3_close(own);
    });
  }

 private:
  void check(int rc, const std::string& sql) {
    if (rc == SQLITE_OK || rc == SQLITE_ROW || rc == SQLITE_DONE) return;
    const std::string what = sqlite3_errmsg(db_);
    if ((rc & 0xff) == SQLITE_CONSTRAINT) throw Error("workspace constraint violated: " + what);
    throw Error("workspace " + path_.string() + ": " + what + " (in: " + sql.substr(0, 80) + ")");
  }

  static constexpr size_t kMaxStatements = 256;
  static constexpr int kCheckpointPages = 1000;  ///< SQLite's own default
  std::thread checkpointer_;
  std::mutex checkpoint_mutex_;
  std::condition_variable checkpoint_wanted_;
  bool checkpoint_due_ = false, stop_ = false;
  std::filesystem::path path_;
  sqlite3* db_ = nullptr;
  std::unordered_map<std::string, sqlite3_stmt*> statements_;  ///< prepared, by their SQL
};

}  // namespace

std::unique_ptr<Database> open_sqlite(const std::filesystem::path& path, const SqliteOptions& options) {
  return std::make_unique<SqliteDatabase>(path, options);
}

}  // namespace artisan::worldmodel
