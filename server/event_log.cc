#include "server/event_log.h"

#include <string>

namespace slapse::server {

void EventLog::SetStore(Persist persist, Backfill backfill) {
  std::lock_guard<std::mutex> lock(mu_);
  persist_ = std::move(persist);
  backfill_ = std::move(backfill);
}

uint64_t EventLog::AppendLocked(std::vector<v1::SessionEvent> events, const Persist& persist) {
  for (v1::SessionEvent& event : events) {
    const uint64_t seq = ++last_sequence_;
    event.set_sequence(seq);
    if (event.has_pose()) event.mutable_pose()->set_sequence(seq);
    if (event.has_plane()) event.mutable_plane()->set_sequence(seq);
  }
  // Durable before visible: a watcher never sees an event the store lacks.
  if (persist) persist(events);
  for (v1::SessionEvent& event : events) ring_.push_back(std::move(event));
  while (ring_.size() > capacity_) ring_.pop_front();
  changed_.notify_all();
  return last_sequence_;
}

uint64_t EventLog::Append(v1::SessionEvent event) {
  std::vector<v1::SessionEvent> one;
  one.push_back(std::move(event));
  std::lock_guard<std::mutex> lock(mu_);
  if (closed_) return 0;  // the final StateChange stays last
  return AppendLocked(std::move(one), persist_);
}

uint64_t EventLog::AppendBatch(std::vector<v1::SessionEvent> events, const Persist& persist) {
  std::lock_guard<std::mutex> lock(mu_);
  if (closed_ || events.empty()) return 0;
  return AppendLocked(std::move(events), persist ? persist : persist_);
}

uint64_t EventLog::Expire(v1::SessionEvent event, const Persist& persist) {
  std::vector<v1::SessionEvent> one;
  one.push_back(std::move(event));
  std::lock_guard<std::mutex> lock(mu_);
  ring_.clear();
  closed_ = true;
  return AppendLocked(std::move(one), persist ? persist : persist_);
}

void EventLog::Close() {
  std::lock_guard<std::mutex> lock(mu_);
  closed_ = true;
  if (backfill_) std::deque<v1::SessionEvent>().swap(ring_);  // frees it; Read backfills
  changed_.notify_all();
}

Status EventLog::Read(uint64_t after_sequence, size_t max_events,
                      std::chrono::steady_clock::time_point deadline,
                      std::vector<v1::SessionEvent>* out, bool* ended) {
  std::unique_lock<std::mutex> lock(mu_);
  *ended = false;
  const size_t before = out->size();  // `out` may hold events already
  changed_.wait_until(lock, deadline, [&] { return closed_ || last_sequence_ > after_sequence; });
  const uint64_t first = ring_.empty() ? last_sequence_ + 1 : ring_.front().sequence();
  if (after_sequence + 1 < first && after_sequence < last_sequence_) {
    const uint64_t last = last_sequence_;
    const bool closed = closed_;
    if (backfill_) {
      // Older than the ring: from the store, which holds every event the
      // ring ever held (persisted before they were appended).
      Backfill backfill = backfill_;
      lock.unlock();
      SLAPSE_RETURN_IF_ERROR(backfill(after_sequence, max_events, out));
      if (out->size() > before) {
        if (closed && out->back().sequence() >= last) *ended = true;
        return Status::Ok();
      }
    }
    return OutOfRangeError("events after sequence " + std::to_string(after_sequence) +
                           " are no longer kept (oldest kept: " + std::to_string(first) +
                           "); fetch a snapshot (GetTrajectory, GetPlaneMap) and "
                           "watch after its last_sequence");
  }
  for (uint64_t seq = after_sequence + 1;
       seq <= last_sequence_ && out->size() - before < max_events; ++seq) {
    out->push_back(ring_[seq - first]);
  }
  if (closed_ && after_sequence + (out->size() - before) >= last_sequence_) *ended = true;
  return Status::Ok();
}

size_t EventLog::events_in_memory() const {
  std::lock_guard<std::mutex> lock(mu_);
  return ring_.size();
}

uint64_t EventLog::last_sequence() const {
  std::lock_guard<std::mutex> lock(mu_);
  return last_sequence_;
}

}  // namespace slapse::server
