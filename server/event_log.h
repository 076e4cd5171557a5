// A session's events with sequence numbers, kept in a bounded ring.
//
// The pipeline appends (never blocks on readers); each watcher reads by
// cursor (the last sequence it has), so a slow watcher costs no memory and
// cannot stall the pipeline or other watchers: if it falls behind the ring it
// reads on from the store (server/store.h), which holds every event.
//
// Thread-safety: all methods may be called concurrently.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <vector>

#include "core/common/status.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::server {

class EventLog {
 public:
  // Writes a batch of events (sequences set) to the store before watchers
  // can see them (server/store.h: the durability rule).
  using Persist = std::function<void(const std::vector<v1::SessionEvent>& events)>;
  // Reads up to `max` events with sequence > after from the store.
  using Backfill =
      std::function<Status(uint64_t after, size_t max, std::vector<v1::SessionEvent>* out)>;

  // capacity: events kept (the oldest are dropped first); at least 1. A log
  // restored after a restart starts after `last_sequence` (its events are in
  // the store), closed if its session had ended.
  explicit EventLog(size_t capacity, uint64_t last_sequence = 0, bool closed = false)
      : capacity_(capacity < 1 ? 1 : capacity), last_sequence_(last_sequence), closed_(closed) {}

  // The store behind the ring: `persist` by default for Append, `backfill`
  // for cursors older than the ring. Call before any Append or Read.
  void SetStore(Persist persist, Backfill backfill);

  // Assigns the next sequence number (also into the event's PoseUpdate or
  // PlaneEvent), persists the event, stores it in the ring and wakes
  // watchers. Returns the sequence, or 0 (event dropped) once the log is
  // closed.
  uint64_t Append(v1::SessionEvent event);
  // As Append for several events at once, persisted by `persist` (one
  // transaction with the rest of a step) instead of the default. Returns the
  // last sequence, or 0 (all dropped) once the log is closed.
  uint64_t AppendBatch(std::vector<v1::SessionEvent> events, const Persist& persist);
  // Retention: the log keeps only `event` (appended even though the log is
  // closed), persisted by `persist`. Returns its sequence.
  uint64_t Expire(v1::SessionEvent event, const Persist& persist);
  // No more events will come; watchers end after draining. With a store
  // behind it the ring's memory is released (watchers drain from the store,
  // which holds every event): a finished session costs no event memory, so
  // a server's memory does not grow with the sessions it has finished.
  void Close();

  // Copies up to `max_events` events with sequence > after_sequence into
  // `out`, waiting until `deadline` for at least one. Events older than the
  // ring come from the store (backfill). Returns OK with events (possibly
  // none at the deadline); OUT_OF_RANGE if events after the cursor are
  // neither in the ring nor in the store. Sets `*ended` when the log is
  // closed and nothing follows the cursor.
  Status Read(uint64_t after_sequence, size_t max_events,
              std::chrono::steady_clock::time_point deadline, std::vector<v1::SessionEvent>* out,
              bool* ended);

  uint64_t last_sequence() const;
  // Events held in memory (the ring).
  size_t events_in_memory() const;

 private:
  uint64_t AppendLocked(std::vector<v1::SessionEvent> events, const Persist& persist);

  const size_t capacity_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  std::deque<v1::SessionEvent> ring_;  // sequences first_sequence_ .. last_sequence_
  uint64_t last_sequence_ = 0;
  bool closed_ = false;
  Persist persist_;
  Backfill backfill_;
};

}  // namespace slapse::server
