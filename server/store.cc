#include "server/store.h"

#include <sqlite3.h>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>

namespace slapse::server {
namespace {

constexpr const char* kSchema = R"sql(
CREATE TABLE IF NOT EXISTS sessions(
  ordinal INTEGER PRIMARY KEY AUTOINCREMENT,
  name TEXT NOT NULL UNIQUE,
  state INTEGER NOT NULL,
  update_time_s INTEGER NOT NULL,
  metric INTEGER NOT NULL DEFAULT 0,
  proto BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS events(
  ordinal INTEGER NOT NULL, seq INTEGER NOT NULL, data BLOB NOT NULL,
  PRIMARY KEY(ordinal, seq)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS points(
  ordinal INTEGER NOT NULL, n INTEGER NOT NULL, segment INTEGER NOT NULL,
  anchor_index INTEGER NOT NULL, timestamp_s REAL NOT NULL, data BLOB NOT NULL,
  PRIMARY KEY(ordinal, n)) WITHOUT ROWID;
-- A revised pose finds the row of its frame (CommitStep).
CREATE INDEX IF NOT EXISTS points_by_frame ON points(ordinal, segment, anchor_index);
CREATE TABLE IF NOT EXISTS planes(
  ordinal INTEGER NOT NULL, segment INTEGER NOT NULL, track_id INTEGER NOT NULL,
  data BLOB NOT NULL,
  PRIMARY KEY(ordinal, segment, track_id)) WITHOUT ROWID;
)sql";

constexpr int64_t kSegmentStride = int64_t{1} << 31;

std::string Serialize(const google::protobuf::MessageLite& m) {
  std::string out;
  m.SerializeToString(&out);
  return out;
}

void BindBlob(sqlite3_stmt* st, int i, const std::string& bytes) {
  sqlite3_bind_blob(st, i, bytes.data(), static_cast<int>(bytes.size()), SQLITE_TRANSIENT);
}

template <typename Message>
bool ParseColumn(sqlite3_stmt* st, int i, Message* m) {
  return m->ParseFromArray(sqlite3_column_blob(st, i), sqlite3_column_bytes(st, i));
}

}  // namespace

std::string DefaultDataDir() {
  if (const char* xdg = std::getenv("XDG_DATA_HOME"); xdg != nullptr && *xdg != '\0') {
    return std::string(xdg) + "/slapse";
  }
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') {
    return std::string(home) + "/.local/share/slapse";
  }
  return "./slapse-data";
}

StatusOr<std::unique_ptr<Store>> Store::Open(const std::string& data_dir) {
  std::string path = data_dir;
  int lock_fd = -1;
  if (data_dir != kInMemoryDataDir) {
    std::error_code ec;
    std::filesystem::create_directories(data_dir, ec);
    if (ec) {
      return FailedPreconditionError("cannot create the data directory '" + data_dir +
                                     "': " + ec.message() + " (serve --data-dir)");
    }
    path = data_dir + "/" + kStoreFileName;
    // One server per data directory: two would both resume its sessions.
    // The kernel drops the lock when the process dies (also by kill -9).
    lock_fd = open((data_dir + "/slapse.lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (lock_fd < 0 || flock(lock_fd, LOCK_EX | LOCK_NB) != 0) {
      if (lock_fd >= 0) close(lock_fd);
      return FailedPreconditionError("the data directory '" + data_dir +
                                     "' is in use by another slapse server (serve --data-dir)");
    }
  }
  sqlite3* db = nullptr;
  const int rc = sqlite3_open_v2(
      path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr);
  std::unique_ptr<Store> store(new Store(db));
  store->lock_fd_ = lock_fd;
  if (rc != SQLITE_OK) {
    return FailedPreconditionError("cannot open the database '" + path +
                                   "': " + sqlite3_errstr(rc) + " (serve --data-dir)");
  }
  sqlite3_busy_timeout(db, 5000);
  // auto_vacuum takes effect only on a new database (before its first table).
  for (const char* sql : {"PRAGMA auto_vacuum=INCREMENTAL", "PRAGMA journal_mode=WAL",
                          "PRAGMA synchronous=NORMAL", "PRAGMA foreign_keys=OFF", kSchema}) {
    Status s = store->Exec(sql);
    if (!s.ok()) {
      return FailedPreconditionError("the database '" + path + "' is not usable: " + s.message());
    }
  }
  return store;
}

Store::~Store() {
  for (auto& [sql, st] : statements_) sqlite3_finalize(st);
  sqlite3_close(db_);
  if (lock_fd_ >= 0) close(lock_fd_);
}

Status Store::Exec(const std::string& sql) {
  char* message = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &message) != SQLITE_OK) {
    std::string text = message != nullptr ? message : "unknown error";
    sqlite3_free(message);
    return InternalError("store: " + text);
  }
  return Status::Ok();
}

Status Store::Error(const std::string& what) const {
  return InternalError("store: " + what + ": " + sqlite3_errmsg(db_));
}

sqlite3_stmt* Store::Prepare(const char* sql) {
  for (auto& [text, st] : statements_) {
    if (text == sql) {
      sqlite3_reset(st);
      sqlite3_clear_bindings(st);
      return st;
    }
  }
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v3(db_, sql, -1, SQLITE_PREPARE_PERSISTENT, &st, nullptr) != SQLITE_OK) {
    return nullptr;
  }
  statements_.emplace_back(sql, st);
  return st;
}

int64_t Store::PragmaLocked(const char* pragma) {
  sqlite3_stmt* st = Prepare(pragma);
  if (st == nullptr) return -1;
  const int64_t value = sqlite3_step(st) == SQLITE_ROW ? sqlite3_column_int64(st, 0) : -1;
  sqlite3_reset(st);  // no read transaction left open
  return value;
}

int64_t Store::SizeBytes() {
  std::lock_guard<std::mutex> lock(mu_);
  const int64_t pages = PragmaLocked("PRAGMA page_count");
  const int64_t free_pages = PragmaLocked("PRAGMA freelist_count");
  const int64_t page_bytes = PragmaLocked("PRAGMA page_size");
  if (pages < 0 || free_pages < 0 || page_bytes < 0) return 0;
  return (pages - free_pages) * page_bytes;
}

Status Store::Reclaim() {
  std::lock_guard<std::mutex> lock(mu_);
  // A statement left on a row holds a read transaction, which would keep the
  // checkpoint from truncating the WAL.
  for (auto& [sql, statement] : statements_) sqlite3_reset(statement);
  // incremental_vacuum frees pages one row step at a time: step to the end.
  sqlite3_stmt* st = Prepare("PRAGMA incremental_vacuum");
  if (st == nullptr) return Error("prepare");
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
  }
  if (rc != SQLITE_DONE) return Error("incremental vacuum");
  return Exec("PRAGMA wal_checkpoint(TRUNCATE)");
}

StatusOr<int64_t> Store::AddSession(const v1::Session& session) {
  std::lock_guard<std::mutex> lock(mu_);
  sqlite3_stmt* st =
      Prepare("INSERT INTO sessions(name, state, update_time_s, proto) VALUES(?1, ?2, ?3, ?4)");
  if (st == nullptr) return Error("prepare");
  sqlite3_bind_text(st, 1, session.name().c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_int(st, 2, session.state());
  sqlite3_bind_int64(st, 3, session.update_time().seconds());
  BindBlob(st, 4, Serialize(session));
  if (sqlite3_step(st) != SQLITE_DONE) return Error("add session " + session.name());
  return sqlite3_last_insert_rowid(db_);
}

Status Store::Commit(int64_t ordinal, const StoreStep& step,
                     const std::vector<v1::SessionEvent>& events) {
  std::lock_guard<std::mutex> lock(mu_);
  SLAPSE_RETURN_IF_ERROR(Exec("BEGIN"));
  Status s = CommitLocked(ordinal, step, events);
  if (!s.ok()) {
    (void)Exec("ROLLBACK");
    return s;
  }
  return Exec("COMMIT");
}

Status Store::CommitLocked(int64_t ordinal, const StoreStep& step,
                           const std::vector<v1::SessionEvent>& events) {
  auto run = [&](sqlite3_stmt* st, const char* what) {
    return st != nullptr && sqlite3_step(st) == SQLITE_DONE ? Status::Ok() : Error(what);
  };
  if (step.session != nullptr) {
    sqlite3_stmt* st = Prepare(
        "UPDATE sessions SET state = ?2, update_time_s = ?3, proto = ?4, metric = ?5"
        " WHERE ordinal = ?1");
    if (st == nullptr) return Error("prepare");
    sqlite3_bind_int64(st, 1, ordinal);
    sqlite3_bind_int(st, 2, step.session->state());
    sqlite3_bind_int64(st, 3, step.session->update_time().seconds());
    BindBlob(st, 4, Serialize(*step.session));
    sqlite3_bind_int(st, 5, step.metric ? 1 : 0);
    SLAPSE_RETURN_IF_ERROR(run(st, "write session"));
  }
  for (auto [replace, sql] :
       {std::pair{step.replace_points, "DELETE FROM points WHERE ordinal = ?1 AND segment = ?2"},
        std::pair{step.replace_planes, "DELETE FROM planes WHERE ordinal = ?1 AND segment = ?2"}}) {
    if (!replace) continue;
    sqlite3_stmt* st = Prepare(sql);
    if (st == nullptr) return Error("prepare");
    sqlite3_bind_int64(st, 1, ordinal);
    sqlite3_bind_int(st, 2, step.segment);
    SLAPSE_RETURN_IF_ERROR(run(st, "replace"));
  }
  // A point of a frame the segment already holds is a revision of its pose:
  // it replaces that row in place (same n, so pages keep display order);
  // others are appended.
  for (const auto& p : step.points) {
    sqlite3_stmt* up = Prepare(
        "UPDATE points SET timestamp_s = ?4, data = ?5 WHERE ordinal = ?1 AND segment = ?2 AND "
        "anchor_index = ?3");
    if (up == nullptr) return Error("prepare");
    sqlite3_bind_int64(up, 1, ordinal);
    sqlite3_bind_int(up, 2, step.segment);
    sqlite3_bind_int64(up, 3, p.anchor_index());
    sqlite3_bind_double(up, 4, p.timestamp_s());
    BindBlob(up, 5, Serialize(p));
    SLAPSE_RETURN_IF_ERROR(run(up, "revise point"));
    if (sqlite3_changes(db_) > 0) continue;
    sqlite3_stmt* st = Prepare(
        "INSERT INTO points(ordinal, n, segment, anchor_index, timestamp_s, data) VALUES(?1, "
        "(SELECT IFNULL(MAX(n), 0) + 1 FROM points WHERE ordinal = ?1), ?2, ?3, ?4, ?5)");
    if (st == nullptr) return Error("prepare");
    sqlite3_bind_int64(st, 1, ordinal);
    sqlite3_bind_int(st, 2, step.segment);
    sqlite3_bind_int64(st, 3, p.anchor_index());
    sqlite3_bind_double(st, 4, p.timestamp_s());
    BindBlob(st, 5, Serialize(p));
    SLAPSE_RETURN_IF_ERROR(run(st, "write point"));
  }
  for (const auto& p : step.planes) {
    sqlite3_stmt* st = Prepare(
        "INSERT OR REPLACE INTO planes(ordinal, segment, track_id, data) VALUES(?1, ?2, ?3, ?4)");
    if (st == nullptr) return Error("prepare");
    sqlite3_bind_int64(st, 1, ordinal);
    sqlite3_bind_int(st, 2, step.segment);
    sqlite3_bind_int(st, 3, p.track_id());
    BindBlob(st, 4, Serialize(p));
    SLAPSE_RETURN_IF_ERROR(run(st, "write plane"));
  }
  for (const auto& e : events) {
    sqlite3_stmt* st = Prepare("INSERT INTO events(ordinal, seq, data) VALUES(?1, ?2, ?3)");
    if (st == nullptr) return Error("prepare");
    sqlite3_bind_int64(st, 1, ordinal);
    sqlite3_bind_int64(st, 2, static_cast<int64_t>(e.sequence()));
    BindBlob(st, 3, Serialize(e));
    SLAPSE_RETURN_IF_ERROR(run(st, "write event"));
  }
  return Status::Ok();
}

Status Store::DeleteSession(int64_t ordinal) {
  std::lock_guard<std::mutex> lock(mu_);
  SLAPSE_RETURN_IF_ERROR(Exec("BEGIN"));
  for (const char* table : {"events", "points", "planes", "sessions"}) {
    Status s =
        Exec(std::string("DELETE FROM ") + table + " WHERE ordinal = " + std::to_string(ordinal));
    if (!s.ok()) {
      (void)Exec("ROLLBACK");
      return s;
    }
  }
  return Exec("COMMIT");
}

Status Store::ExpireResults(int64_t ordinal, const v1::Session& session,
                            uint64_t keep_from_sequence) {
  std::lock_guard<std::mutex> lock(mu_);
  SLAPSE_RETURN_IF_ERROR(Exec("BEGIN"));
  const std::string where = " WHERE ordinal = " + std::to_string(ordinal);
  Status s = Exec("DELETE FROM points" + where);
  if (s.ok()) s = Exec("DELETE FROM planes" + where);
  if (s.ok())
    s = Exec("DELETE FROM events" + where + " AND seq < " + std::to_string(keep_from_sequence));
  if (s.ok()) {
    StoreStep row;
    row.session = &session;
    s = CommitLocked(ordinal, row, {});
  }
  if (!s.ok()) {
    (void)Exec("ROLLBACK");
    return s;
  }
  return Exec("COMMIT");
}

StatusOr<std::vector<StoredSession>> Store::LoadSessions() {
  std::lock_guard<std::mutex> lock(mu_);
  sqlite3_stmt* st = Prepare(
      "SELECT s.ordinal, s.proto,"
      " (SELECT IFNULL(MAX(seq), 0) FROM events e WHERE e.ordinal = s.ordinal),"
      // Index lookups only (no scan of a long session's points): the last
      // point has the highest number, segment and anchor index.
      " (SELECT IFNULL(MAX(n), 0) FROM points p WHERE p.ordinal = s.ordinal),"
      " MAX(IFNULL((SELECT segment FROM points p WHERE p.ordinal = s.ordinal"
      "             ORDER BY n DESC LIMIT 1), -1),"
      "     (SELECT IFNULL(MAX(segment), -1) FROM planes q WHERE q.ordinal = s.ordinal)),"
      " IFNULL((SELECT anchor_index FROM points p WHERE p.ordinal = s.ordinal"
      "         ORDER BY n DESC LIMIT 1), -1),"
      " s.metric"
      " FROM sessions s ORDER BY s.ordinal");
  if (st == nullptr) return Error("prepare");
  std::vector<StoredSession> out;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    StoredSession s;
    s.ordinal = sqlite3_column_int64(st, 0);
    if (!ParseColumn(st, 1, &s.proto)) {
      return DataLossError("store: session row " + std::to_string(s.ordinal) +
                           " does not parse as a v1.Session");
    }
    s.last_sequence = static_cast<uint64_t>(sqlite3_column_int64(st, 2));
    s.points = sqlite3_column_int64(st, 3);
    s.max_segment = sqlite3_column_int(st, 4);
    s.max_anchor_index = sqlite3_column_int64(st, 5);
    s.metric = sqlite3_column_int(st, 6) != 0;
    out.push_back(std::move(s));
  }
  if (rc != SQLITE_DONE) return Error("load sessions");
  return out;
}

Status Store::ReadEvents(int64_t ordinal, uint64_t after, size_t max,
                         std::vector<v1::SessionEvent>* out) {
  std::lock_guard<std::mutex> lock(mu_);
  sqlite3_stmt* st =
      Prepare("SELECT data FROM events WHERE ordinal = ?1 AND seq > ?2 ORDER BY seq LIMIT ?3");
  if (st == nullptr) return Error("prepare");
  sqlite3_bind_int64(st, 1, ordinal);
  sqlite3_bind_int64(st, 2, static_cast<int64_t>(after));
  sqlite3_bind_int64(st, 3, static_cast<int64_t>(max));
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    out->emplace_back();
    if (!ParseColumn(st, 0, &out->back())) return DataLossError("store: an event does not parse");
  }
  return rc == SQLITE_DONE ? Status::Ok() : Error("read events");
}

Status Store::ReadPoints(int64_t ordinal, int64_t after_n, double start_s, double end_s, size_t max,
                         std::vector<v1::Trajectory::Point>* out, std::vector<int64_t>* numbers) {
  std::lock_guard<std::mutex> lock(mu_);
  sqlite3_stmt* st = Prepare(
      "SELECT n, data FROM points WHERE ordinal = ?1 AND n > ?2 AND timestamp_s >= ?3"
      " AND (?4 <= 0 OR timestamp_s < ?4) ORDER BY n LIMIT ?5");
  if (st == nullptr) return Error("prepare");
  sqlite3_bind_int64(st, 1, ordinal);
  sqlite3_bind_int64(st, 2, after_n);
  sqlite3_bind_double(st, 3, start_s);
  sqlite3_bind_double(st, 4, end_s);
  sqlite3_bind_int64(st, 5, static_cast<int64_t>(max));
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    numbers->push_back(sqlite3_column_int64(st, 0));
    out->emplace_back();
    if (!ParseColumn(st, 1, &out->back())) return DataLossError("store: a point does not parse");
  }
  return rc == SQLITE_DONE ? Status::Ok() : Error("read points");
}

int64_t Store::CountPoints(int64_t ordinal) {
  std::lock_guard<std::mutex> lock(mu_);
  sqlite3_stmt* st = Prepare("SELECT COUNT(*) FROM points WHERE ordinal = ?1");
  if (st == nullptr) return 0;
  sqlite3_bind_int64(st, 1, ordinal);
  return sqlite3_step(st) == SQLITE_ROW ? sqlite3_column_int64(st, 0) : 0;
}

Status Store::ReadPlanes(int64_t ordinal, int64_t after_key, size_t max,
                         std::vector<v1::PlaneMap::Plane>* out, int64_t* last_key) {
  std::lock_guard<std::mutex> lock(mu_);
  sqlite3_stmt* st = Prepare(
      "SELECT segment * ?2 + track_id AS k, data FROM planes WHERE ordinal = ?1"
      " AND segment * ?2 + track_id > ?3 ORDER BY segment, track_id LIMIT ?4");
  if (st == nullptr) return Error("prepare");
  sqlite3_bind_int64(st, 1, ordinal);
  sqlite3_bind_int64(st, 2, kSegmentStride);
  sqlite3_bind_int64(st, 3, after_key);
  sqlite3_bind_int64(st, 4, static_cast<int64_t>(max));
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    *last_key = sqlite3_column_int64(st, 0);
    out->emplace_back();
    if (!ParseColumn(st, 1, &out->back())) return DataLossError("store: a plane does not parse");
  }
  return rc == SQLITE_DONE ? Status::Ok() : Error("read planes");
}

}  // namespace slapse::server
