// A session's events with sequence numbers, kept in a bounded ring.
//
// The pipeline appends (never blocks on readers); each watcher reads by
// cursor (the last sequence it has), so a slow watcher costs no memory and
// cannot stall the pipeline or other watchers: if it falls behind the ring it
// gets OUT_OF_RANGE and resumes from a snapshot.
//
// Thread-safety: all methods may be called concurrently.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <vector>

#include "core/common/status.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::server {

class EventLog {
 public:
  // capacity: events kept (the oldest are dropped first); at least 1.
  explicit EventLog(size_t capacity) : capacity_(capacity < 1 ? 1 : capacity) {}

  // Assigns the next sequence number (also into the event's PoseUpdate or
  // PlaneEvent), stores the event and wakes watchers. Returns the sequence,
  // or 0 (event dropped) once the log is closed.
  uint64_t Append(v1::SessionEvent event);
  // No more events will come; watchers end after draining.
  void Close();

  // Copies up to `max_events` events with sequence > after_sequence into
  // `out`, waiting until `deadline` for at least one. Returns OK with events
  // (possibly none at the deadline); OUT_OF_RANGE if events after the cursor
  // were already dropped from the ring. Sets `*ended` when the log is closed
  // and nothing follows the cursor.
  Status Read(uint64_t after_sequence, size_t max_events,
              std::chrono::steady_clock::time_point deadline, std::vector<v1::SessionEvent>* out,
              bool* ended);

  uint64_t last_sequence() const;

 private:
  const size_t capacity_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  std::deque<v1::SessionEvent> ring_;  // sequences first_sequence_ .. last_sequence_
  uint64_t last_sequence_ = 0;
  bool closed_ = false;
};

}  // namespace slapse::server
