#include "server/upload_queue.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>

namespace slapse::server {

UploadQueue::UploadQueue(UploadQueueOptions options)
    : options_(options), created_(Clock::now()), last_write_(created_) {}

void UploadQueue::Start() {
  std::lock_guard<std::mutex> lock(mu_);
  started_ = true;
  last_write_ = Clock::now();
  readable_.notify_all();  // the waiting reader takes the stall deadline
}

Status UploadQueue::Write(std::string bytes, const std::function<bool()>& cancelled) {
  std::unique_lock<std::mutex> lock(mu_);
  if (closed_) return close_reason_;
  if (finished_) return FailedPreconditionError("the upload was already finished");
  const int64_t n = static_cast<int64_t>(bytes.size());
  if (options_.max_total_bytes > 0 && total_ + n > options_.max_total_bytes) {
    Status s = ResourceExhaustedError("upload exceeds the server's limit of " +
                                      std::to_string(options_.max_total_bytes) +
                                      " bytes per session (serve --max-upload-mb)");
    lock.unlock();
    Close(s);
    return s;
  }
  // A chunk larger than the whole buffer is admitted into an empty buffer.
  while (!closed_ && buffered_ > 0 && buffered_ + n > options_.capacity_bytes) {
    if (cancelled && cancelled()) return CancelledError("the upload was cancelled");
    writable_.wait_for(lock, std::chrono::milliseconds(50));
  }
  if (closed_) return close_reason_;
  if (n == 0) return Status::Ok();
  last_write_ = Clock::now();
  buffered_ += n;
  total_ += n;
  chunks_.push_back(std::move(bytes));
  readable_.notify_all();
  return Status::Ok();
}

void UploadQueue::Finish() {
  std::lock_guard<std::mutex> lock(mu_);
  finished_ = true;
  readable_.notify_all();
}

void UploadQueue::Close(Status reason) {
  std::lock_guard<std::mutex> lock(mu_);
  CloseLocked(std::move(reason));
}

void UploadQueue::CloseLocked(Status reason) {
  if (closed_) return;
  closed_ = true;
  close_reason_ = reason.ok() ? CancelledError("the session ended") : std::move(reason);
  chunks_.clear();
  buffered_ = 0;
  readable_.notify_all();
  writable_.notify_all();
}

Status UploadQueue::IdleTimeoutErrorLocked() const {
  const auto seconds = [](int64_t ms) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%g", ms / 1000.0);
    return std::string(buf);
  };
  if (started_) {
    return Status(StatusCode::kDeadlineExceeded,
                  "the upload stalled: no bytes arrived for " + seconds(options_.stall_timeout_ms) +
                      " s (serve --upload-stall-timeout-s); the session's worker is freed");
  }
  return Status(StatusCode::kDeadlineExceeded,
                "no upload began within " + seconds(options_.start_idle_timeout_ms) +
                    " s of the session's creation (serve --create-idle-timeout-s); the "
                    "session's worker is freed");
}

UploadQueue::Clock::time_point UploadQueue::IdleDeadlineLocked() const {
  const int64_t ms = started_ ? options_.stall_timeout_ms : options_.start_idle_timeout_ms;
  if (ms <= 0) return Clock::time_point::max();
  return (started_ ? last_write_ : created_) + std::chrono::milliseconds(ms);
}

int UploadQueue::Read(uint8_t* buf, int size) { return Read(buf, size, nullptr); }

int UploadQueue::Read(uint8_t* buf, int size, const std::function<bool()>& interrupt) {
  std::unique_lock<std::mutex> lock(mu_);
  auto ready = [&] { return closed_ || finished_ || !chunks_.empty(); };
  while (!ready()) {
    const Clock::time_point deadline = IdleDeadlineLocked();
    if (Clock::now() >= deadline) {
      CloseLocked(IdleTimeoutErrorLocked());
      break;
    }
    if (interrupt) {
      if (interrupt()) return -1;
      readable_.wait_until(lock, std::min(deadline, Clock::now() + std::chrono::milliseconds(50)));
    } else if (deadline == Clock::time_point::max()) {
      readable_.wait(lock);
    } else {
      readable_.wait_until(lock, deadline);
    }
  }
  if (closed_) return -1;
  if (chunks_.empty()) return 0;  // finished and drained
  int copied = 0;
  while (copied < size && !chunks_.empty()) {
    const std::string& front = chunks_.front();
    const size_t n = std::min(static_cast<size_t>(size - copied), front.size() - head_offset_);
    std::memcpy(buf + copied, front.data() + head_offset_, n);
    copied += static_cast<int>(n);
    head_offset_ += n;
    if (head_offset_ == front.size()) {
      chunks_.pop_front();
      head_offset_ = 0;
    }
  }
  buffered_ -= copied;
  writable_.notify_all();
  return copied;
}

int64_t UploadQueue::total_bytes() const {
  std::lock_guard<std::mutex> lock(mu_);
  return total_;
}

}  // namespace slapse::server

namespace slapse::server {

Status UploadQueue::close_reason() const {
  std::lock_guard<std::mutex> lock(mu_);
  return closed_ ? close_reason_ : Status::Ok();
}

}  // namespace slapse::server
