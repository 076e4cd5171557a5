// Session: one session's state machine and what it holds for readers.
//
// States: CREATED -> RUNNING -> FINISHED / FAILED / STOPPED (terminal; a
// session can also end straight from CREATED). Every transition appends a
// StateChange to the session's event log; a terminal one closes the log and
// the upload queue. How a session ends: STOPPED whenever it was asked to stop
// (StopSession, DeleteSession, shutdown), else what its source says
// (End / EndStream). Its results (events, trajectory, plane map) live in the
// server's store (server/store.h), written before watchers see them; RAM
// holds the state, the counters and the recent events' ring only, so a
// session's memory does not grow with its length.
//
// Thread-safety: `mu` guards the fields below it; the methods take it
// (the *Locked ones expect it held).
#pragma once

#include <atomic>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "server/event_log.h"
#include "server/frame_overlays.h"
#include "server/store.h"
#include "server/upload_queue.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::server {

bool IsTerminal(v1::Session::State state);

// How a session ends: the state, and for FAILED the error (else a message).
struct Ending {
  v1::Session::State state = v1::Session::FAILED;
  Status error;
  std::string message;
};

class Session {
 public:
  // `store` holds the session as row `ordinal`; a session restored after a
  // restart has events up to `last_sequence` already (`closed`: it had ended).
  Session(std::string name, size_t event_ring_capacity, UploadQueueOptions upload,
          std::shared_ptr<Store> store = nullptr, int64_t ordinal = 0, uint64_t last_sequence = 0,
          bool closed = false);

  const std::string name;
  const std::shared_ptr<Store> store;
  const int64_t ordinal;             // the store's key; creation order
  std::shared_ptr<EventLog> events;  // shared with watchers
  std::shared_ptr<UploadQueue> upload;
  std::atomic<bool> stop{false};
  std::condition_variable stop_cv;  // with `mu`: wakes a reconnect wait on stop
  // The newest anchor frame as pictures for the dashboard (own lock).
  const std::shared_ptr<FrameOverlays> overlays = std::make_shared<FrameOverlays>();

  mutable std::mutex mu;  // guards everything below
  v1::Session proto;      // state, stats, error, times (last_sequence filled on read)
  bool upload_started = false;
  bool suspended = false;  // Suspend(): no more transitions
  Status ingest_error;     // why the upload broke off, if it did
  int64_t points = 0;      // trajectory points (in the store)
  int segment = 0;         // +1 at each resume after a restart (Trajectory.Point.segment)
  // Resumed after a restart: the last frame index before it (the runner
  // continues the timeline after it); -1 otherwise.
  int64_t resumed_last_index = -1;
  double resumed_down_s = 0.0;  // and how long before the restart its last update was
  bool metric = false;
  // Why the session has no poses yet (the runner keeps it current); a
  // FINISHED ending with an empty trajectory says it ("no poses: ...").
  std::string no_pose_reason = "no video frames were received";

  // Moves to `state` unless already terminal; appends the StateChange event
  // and, for a terminal state, closes the event log. Call with `mu` held.
  bool TransitionLocked(v1::Session::State state, const Status& why, const std::string& message);
  bool Transition(v1::Session::State state, const Status& why, const std::string& message = "");

  // Asks the session to stop: sets `stop`, wakes a reconnect wait and marks
  // it STOPPED with `why`.
  void Stop(const std::string& why);
  // Server shutdown with a persistent store: stops the run WITHOUT ending
  // the session (it stays CREATED / RUNNING in the store and resumes after
  // the restart); ends its watchers (UNAVAILABLE) and its upload.
  void Suspend();

  // Waits up to `ms` or until the session is asked to stop; true if it was.
  bool WaitForStop(int ms);

  // Ends the session: STOPPED if it was asked to stop, else `ending`.
  void End(const Ending& ending);
  // Ends the session after its stream broke off with `status` (the upload's
  // own error, if it broke off, wins): STOPPED if asked to stop, FINISHED
  // with `finished_message` at the end of the stream (OUT_OF_RANGE), else
  // FAILED with the status.
  void EndStream(Status status, const std::string& finished_message);

  // The session as Get returns it (last_sequence filled in).
  v1::Session Snapshot() const;

  // Writes one step to the store with its `events` (the runner's
  // EventLog::AppendBatch persist); logs a store failure.
  void CommitStep(const StoreStep& step, const std::vector<v1::SessionEvent>& events) const;

  // Retention: a terminal session becomes EXPIRED with `message`; its
  // results are deleted from the store. False if not terminal.
  bool Expire(const std::string& message);
};

}  // namespace slapse::server
