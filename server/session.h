// Session: one session's state machine and what it holds for readers.
//
// States: CREATED -> RUNNING -> FINISHED / FAILED / STOPPED (terminal; a
// session can also end straight from CREATED). Every transition appends a
// StateChange to the session's event log; a terminal one closes the log and
// the upload queue. How a session ends: STOPPED whenever it was asked to stop
// (StopSession, DeleteSession, shutdown), else what its source says
// (End / EndStream). The snapshots (trajectory, plane map) are kept here for
// GetTrajectory / GetPlaneMap, as wire messages.
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
  Session(std::string name, size_t event_ring_capacity, UploadQueueOptions upload);

  const std::string name;
  std::shared_ptr<EventLog> events;  // shared with watchers
  std::shared_ptr<UploadQueue> upload;
  std::atomic<bool> stop{false};
  std::condition_variable stop_cv;  // with `mu`: wakes a reconnect wait on stop

  mutable std::mutex mu;  // guards everything below
  v1::Session proto;      // state, stats, error, times (last_sequence filled on read)
  bool upload_started = false;
  Status ingest_error;  // why the upload broke off, if it did
  std::vector<v1::Trajectory::Point> trajectory;
  std::map<int, v1::PlaneMap::Plane> planes;
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
};

}  // namespace slapse::server
