#include "server/event_log.h"

#include <string>

namespace slapse::server {

uint64_t EventLog::Append(v1::SessionEvent event) {
  std::lock_guard<std::mutex> lock(mu_);
  if (closed_) return 0;  // the final StateChange stays last
  const uint64_t seq = ++last_sequence_;
  event.set_sequence(seq);
  if (event.has_pose()) event.mutable_pose()->set_sequence(seq);
  if (event.has_plane()) event.mutable_plane()->set_sequence(seq);
  ring_.push_back(std::move(event));
  while (ring_.size() > capacity_) ring_.pop_front();
  changed_.notify_all();
  return seq;
}

void EventLog::Close() {
  std::lock_guard<std::mutex> lock(mu_);
  closed_ = true;
  changed_.notify_all();
}

Status EventLog::Read(uint64_t after_sequence, size_t max_events,
                      std::chrono::steady_clock::time_point deadline,
                      std::vector<v1::SessionEvent>* out, bool* ended) {
  std::unique_lock<std::mutex> lock(mu_);
  *ended = false;
  changed_.wait_until(lock, deadline, [&] { return closed_ || last_sequence_ > after_sequence; });
  const uint64_t first = ring_.empty() ? last_sequence_ + 1 : ring_.front().sequence();
  if (after_sequence + 1 < first) {
    return OutOfRangeError("events after sequence " + std::to_string(after_sequence) +
                           " are no longer kept (oldest kept: " + std::to_string(first) +
                           "); fetch a snapshot (GetTrajectory, GetPlaneMap) and "
                           "watch after its last_sequence");
  }
  for (uint64_t seq = after_sequence + 1; seq <= last_sequence_ && out->size() < max_events;
       ++seq) {
    out->push_back(ring_[seq - first]);
  }
  if (closed_ && after_sequence + out->size() >= last_sequence_) *ended = true;
  return Status::Ok();
}

uint64_t EventLog::last_sequence() const {
  std::lock_guard<std::mutex> lock(mu_);
  return last_sequence_;
}

}  // namespace slapse::server
