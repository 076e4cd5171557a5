// Store: the server's persistence, one SQLite database (WAL) in the data
// directory (serve --data-dir). The one home for SQL.
//
// Tables (by session `ordinal`, its creation order, never reused):
//   sessions(ordinal, name, state, end_time_s, proto)  the whole v1::Session
//       serialized, so new Session fields persist without a schema change
//   events(ordinal, seq, data)                          every SessionEvent
//   points(ordinal, n, segment, timestamp_s, data)      trajectory points
//   planes(ordinal, segment, track_id, data)            the plane map
//
// Durability rule: a step is durable once its event is sent. The session
// commits each step (its events, the new trajectory points and plane rows,
// the session row) in one transaction BEFORE its events enter the in-RAM ring
// that watchers read, so whatever a client has seen survives a crash
// (kill -9) of the server. synchronous=NORMAL in WAL mode: a committed step
// survives a process crash; an OS crash or power loss may lose the last
// steps (the database stays consistent).
//
// Size (SizeBytes, the one measure of the store's size: the
// slapse_store_bytes metric and the retention budget,
// SessionManagerOptions::retention_max_store_bytes): the bytes of the pages
// that hold data, (page_count - freelist_count) * page_size, so a deletion
// counts at once. The file on disk is that plus its free pages plus the WAL.
// A store created by this version has auto_vacuum=INCREMENTAL: Reclaim()
// returns the free pages to the file system and truncates the WAL. A store
// created before keeps auto_vacuum=NONE (changing it needs a VACUUM): its
// free pages are reused by new rows, so the file stops growing but does not
// shrink.
//
// Thread-safety: every method may be called from any thread (one connection
// behind a mutex).
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "slapse/v1/slapse.pb.h"

struct sqlite3;
struct sqlite3_stmt;

namespace slapse::server {

// The database file in `data_dir`.
constexpr const char* kStoreFileName = "slapse.db";
// data_dir value for a database in memory (tests; nothing survives).
constexpr const char* kInMemoryDataDir = ":memory:";

// The data directory `serve` uses by default: $XDG_DATA_HOME/slapse, else
// $HOME/.local/share/slapse, else ./slapse-data.
std::string DefaultDataDir();

// What one pipeline step (or one state change) writes, in one transaction.
struct StoreStep {
  // The session row to write (its state and stats after the step); null:
  // leave it.
  const v1::Session* session = nullptr;
  bool metric = false;  // with `session`: lengths are metres
  // Trajectory points: `replace_points` first deletes the points of
  // `segment` (a rescale re-sends them all); then `points` are appended.
  bool replace_points = false;
  std::vector<v1::Trajectory::Point> points;
  // Plane rows: `replace_planes` first deletes those of `segment`; then each
  // of `planes` is written (by segment and track id).
  bool replace_planes = false;
  std::vector<v1::PlaneMap::Plane> planes;
  int segment = 0;
};

// A session as the store holds it, for a restart.
struct StoredSession {
  int64_t ordinal = 0;
  v1::Session proto;
  bool metric = false;
  uint64_t last_sequence = 0;  // of its events (0: none)
  int64_t points = 0;          // the last point's number (0: no points)
  int max_segment = -1;        // of its points and planes (-1: none)
  int64_t max_anchor_index = -1;
};

class Store {
 public:
  // Opens (creates) `data_dir`/slapse.db, or an in-memory database for
  // kInMemoryDataDir. FAILED_PRECONDITION naming the path when the
  // directory cannot be made or the database cannot be opened.
  static StatusOr<std::unique_ptr<Store>> Open(const std::string& data_dir);
  ~Store();
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;

  // A new session row; returns its ordinal (creation order, never reused).
  StatusOr<int64_t> AddSession(const v1::Session& session);
  // One step of session `ordinal`: `step`, then `events` (sequences set),
  // in one transaction.
  Status Commit(int64_t ordinal, const StoreStep& step,
                const std::vector<v1::SessionEvent>& events);
  // Forgets a session (DeleteSession).
  Status DeleteSession(int64_t ordinal);
  // Retention: deletes the session's events up to `keep_from_sequence`
  // (exclusive), its points and planes; writes its row.
  Status ExpireResults(int64_t ordinal, const v1::Session& session, uint64_t keep_from_sequence);

  // The bytes of data in the store (pages in use, above); an in-memory store
  // counts its pages the same way. 0 if SQLite cannot tell.
  int64_t SizeBytes();
  // Gives the pages freed by deletions back to the file system (incremental
  // vacuum; a no-op on a store with auto_vacuum=NONE, above) and truncates
  // the WAL (checkpoint). Retention calls it after expiring sessions.
  Status Reclaim();

  // Every session in creation order.
  StatusOr<std::vector<StoredSession>> LoadSessions();
  // Up to `max` events with sequence > after, ascending.
  Status ReadEvents(int64_t ordinal, uint64_t after, size_t max,
                    std::vector<v1::SessionEvent>* out);
  // Up to `max` points after point number `after_n` (0: from the first)
  // with start_s <= timestamp_s < end_s (end_s <= 0: no bound), ascending;
  // `numbers` gets each one's point number (a page token).
  Status ReadPoints(int64_t ordinal, int64_t after_n, double start_s, double end_s, size_t max,
                    std::vector<v1::Trajectory::Point>* out, std::vector<int64_t>* numbers);
  int64_t CountPoints(int64_t ordinal);
  // Up to `max` planes after (segment, track id) key `after_key`
  // (segment * 2^31 + track id; -1: from the first), ascending.
  Status ReadPlanes(int64_t ordinal, int64_t after_key, size_t max,
                    std::vector<v1::PlaneMap::Plane>* out, int64_t* last_key);

 private:
  explicit Store(sqlite3* db) : db_(db) {}
  Status Exec(const std::string& sql);
  // The first column of the first row of `pragma` (e.g. "PRAGMA page_count"), -1 on error.
  int64_t PragmaLocked(const char* pragma);
  Status Error(const std::string& what) const;
  // A cached prepared statement for `sql`, reset.
  sqlite3_stmt* Prepare(const char* sql);
  Status CommitLocked(int64_t ordinal, const StoreStep& step,
                      const std::vector<v1::SessionEvent>& events);

  std::mutex mu_;
  sqlite3* db_;
  int lock_fd_ = -1;  // flock on data_dir/slapse.lock
  std::vector<std::pair<const char*, sqlite3_stmt*>> statements_;
};

}  // namespace slapse::server
