// SessionManager: the sessions of a server, one pipeline each, run on a
// bounded pool of worker threads.
//
// A session is active while CREATED or RUNNING; at most `max_sessions` are
// active at once and each holds one worker thread for its whole life (stream
// reads block), so the pool never oversubscribes. Sessions and their results
// persist in a Store (server/store.h) under `data_dir`; Open() restores them
// after a restart. Finished sessions keep their results until deleted or
// until retention expires them (state EXPIRED): after a TTL, or oldest first
// while the store is over its size budget.
//
// After a restart (clean or kill -9): finished sessions are as they were; an
// upload that was running ends FAILED (ABORTED: upload again to a new
// session), one not begun waits for its upload again; RTSP pull sessions
// reconnect by themselves and RTSP push / RTP sessions wait for their sender
// again (CREATED, then RUNNING), their poses in a new segment (a new
// pipeline, so a new world frame: Trajectory.Point.segment).
//
// Thread-safety: every public method may be called from any thread.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "core/common/status.h"
#include "server/event_log.h"
#include "server/rtsp_ingest.h"
#include "server/session.h"
#include "server/store.h"
#include "server/udp_ports.h"
#include "server/worker_pool.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::server {

struct SessionManagerOptions {
  // Sessions active (CREATED or RUNNING) at once; also the worker threads.
  int max_sessions = 4;
  // Bytes one upload may send in total; 0 = no limit.
  int64_t max_upload_bytes = int64_t{4} << 30;
  // Bytes buffered between an upload and its pipeline (backpressure beyond).
  int64_t upload_buffer_bytes = 4 << 20;
  // Upload sessions: one CREATED with no upload begun for this long, or
  // RUNNING with no bytes for upload_stall_timeout_ms, ends FAILED with
  // DEADLINE_EXCEEDED and frees its worker (0 = never). Network sources have
  // their own start_timeout_ms / receive_timeout_ms instead.
  int64_t create_idle_timeout_ms = 10 * 60 * 1000;
  int64_t upload_stall_timeout_ms = 60 * 1000;
  // Events kept in RAM per session for watchers to resume from; a watcher
  // further behind reads on from the store. A live 30 fps session emits ~35
  // events/s, so 1024 are its last ~30 s, ~0.5 MiB (4096 held ~2 MiB more
  // per session, reached after two minutes of stream).
  size_t event_ring_capacity = 1024;
  // RTSP push: the address the server's one RTSP ingest port binds and that
  // ingest URLs name (server/rtsp_ingest.h).
  std::string rtsp_push_host = "127.0.0.1";
  // The host ingest URLs name instead (RtspIngestOptions::url_host); "" =
  // rtsp_push_host.
  std::string rtsp_url_host;
  // The RTSP ingest port of every push session; 0 = a free one
  // (SessionManager::rtsp_port()). `slapse serve` uses 8554.
  int rtsp_port = 0;
  // The UDP ports RTP arrives on (server/udp_ports.h): RTP/SDP sessions'
  // m=video ports must lie in it, and RTSP publishers recording over UDP get
  // their server ports from it. Default: any port.
  UdpPortRange rtp_ports;
  // Where sessions and results persist (server/store.h); kInMemoryDataDir
  // keeps them in memory only (the library's default, for tests and
  // embedding; `slapse serve` defaults to DefaultDataDir()).
  std::string data_dir = kInMemoryDataDir;
  // A finished session's results are deleted this long after it ended (it
  // becomes EXPIRED, with a StateChange saying so); 0 = kept until deleted.
  int64_t retention_ttl_s = 0;
  // A size budget for the store (Store::SizeBytes: the bytes of its pages in
  // use); 0 = none. While the store is over it, the finished sessions
  // (FINISHED, FAILED, STOPPED; never an active one) expire oldest end time
  // first, as by the TTL, until it is under. With only active sessions
  // left over the budget, the log says so (once) and nothing is deleted.
  int64_t retention_max_store_bytes = 0;
  // A session's pipeline keeps this many final poses in memory after each
  // step and forgets the older ones, with the anchors and the planes no
  // longer held (Pipeline::ForgetFinal): the store has them, and a session's
  // memory does not grow with its length.
  size_t final_poses_in_memory = 256;
  // Bytes a session's reader may read to identify its stream
  // (MvReaderOptions::probe_bytes). FFmpeg's default, 5 MB, is also the
  // buffer the MPEG-TS demuxer keeps at the start of every byte stream (RTSP
  // push, upload): 5 MB per session that a live 640x480 stream does not need
  // (its stream facts are read from the first ~0.1 s). 0 = FFmpeg's default.
  int64_t reader_probe_bytes = 1 << 20;
  // The replica this server is in a cluster (api/session_name.h): new
  // sessions are named "sessions/<replica_id>-<random>"; a call for a
  // session of another replica is NOT_FOUND naming both (misrouted). "" =
  // a single server ("sessions/<random>").
  std::string replica_id;
};

// NOT_FOUND for session `name`: "no session '<name>' on this server" (also
// what another tenant's session is, so the two read the same).
Status SessionNotFoundError(const std::string& name);

class SessionManager {
 public:
  explicit SessionManager(SessionManagerOptions options);
  // Stops every session and joins the workers (as Shutdown()).
  ~SessionManager();
  SessionManager(const SessionManager&) = delete;
  SessionManager& operator=(const SessionManager&) = delete;

  // Opens the store, starts the RTSP ingest port and restores the sessions
  // (above). Call once before serving; FAILED_PRECONDITION if the data
  // directory is unusable, UNAVAILABLE if the RTSP port cannot be bound.
  Status Open();
  // The RTSP ingest port (after Open), 0 if not started.
  int rtsp_port() const;
  // The store's size (Store::SizeBytes), 0 before Open.
  int64_t StoreBytes() const;

  // Validates and starts a session from `request` (source, intrinsics,
  // pipeline options). INVALID_ARGUMENT (also a bad RTSP pull URL or
  // reconnect policy, RTSP push path or SDP), RESOURCE_EXHAUSTED (at capacity)
  // or UNAVAILABLE (shutting down, or no free port for an RTSP listener).
  StatusOr<v1::Session> Create(const v1::Session& request);
  StatusOr<v1::Session> Get(const std::string& name) const;
  // One page of the query (filter, order_by, page; api/list_query.h).
  // With `tenant`, only that tenant's sessions (Session.tenant); null = all.
  StatusOr<v1::ListSessionsResponse> List(const v1::ListSessionsRequest& request,
                                          const std::string* tenant = nullptr) const;
  Status Delete(const std::string& name);
  StatusOr<v1::Session> Stop(const std::string& name);

  // Feeds one upload session. `next` fills the next chunk and returns false at
  // the end of the client's stream; `cancelled` reports a cancelled rpc.
  // The first chunk's name has been read by the caller.
  StatusOr<v1::Session> Upload(const std::string& name, std::string first_bytes,
                               const std::function<bool(std::string*)>& next,
                               const std::function<bool()>& cancelled);

  // A session's event log, for a watcher to read (EventLog::Read). The log
  // outlives a Delete of its session, so a watcher still drains to the final
  // StateChange. NOT_FOUND if unknown.
  StatusOr<std::shared_ptr<EventLog>> Events(const std::string& name) const;
  // A session's latest-frame overlays (server/frame_overlays.h). NOT_FOUND if unknown.
  StatusOr<std::shared_ptr<FrameOverlays>> Overlays(const std::string& name) const;

  // Snapshots, a page at a time (see GetTrajectoryRequest). FAILED_PRECONDITION
  // for an EXPIRED session.
  StatusOr<v1::Trajectory> GetTrajectory(const v1::GetTrajectoryRequest& request) const;
  StatusOr<v1::PlaneMap> GetPlaneMap(const v1::GetPlaneMapRequest& request) const;

  // Refuses new sessions, stops the active ones (they end STOPPED, their
  // watchers end) and joins the workers. Idempotent.
  void Shutdown();

 private:
  // INVALID_ARGUMENT for a malformed name, NOT_FOUND for an unknown one.
  StatusOr<std::shared_ptr<Session>> Find(const std::string& name) const;
  int ActiveCountLocked() const;
  UploadQueueOptions QueueOptions() const;
  // Restores one stored session; resumes it if it was active.
  void Restore(StoredSession stored);
  // Retention: every period until Shutdown, the TTL pass then the budget
  // pass, then the store's free pages go back (Store::Reclaim).
  void RetentionLoop();
  // Expires the finished sessions that ended more than retention_ttl_s ago.
  int ExpireByTtl(const std::vector<std::shared_ptr<Session>>& all);
  // Expires finished sessions, oldest end first, while the store is over
  // retention_max_store_bytes.
  int ExpireOverBudget(const std::vector<std::shared_ptr<Session>>& all);

  const SessionManagerOptions options_;
  std::shared_ptr<Store> store_;
  mutable std::mutex mu_;
  std::map<int64_t, std::shared_ptr<Session>> sessions_;  // by ordinal = creation order
  std::map<std::string, int64_t> ordinals_;               // name -> ordinal
  bool shutting_down_ = false;
  std::condition_variable retention_cv_;  // with mu_: wakes the loop at Shutdown
  std::thread retention_;
  bool over_budget_logged_ = false;   // retention thread only: "only active sessions" said
  std::unique_ptr<RtspIngest> rtsp_;  // RTSP push mounts; outlives the workers
  WorkerPool pool_;                   // one thread per active session; last, so it stops first
};

}  // namespace slapse::server
