// The byte queue between an UploadStream rpc (producer) and a session's
// MvReader (consumer): bounded memory, backpressure on the uploader.
//
// Thread-safety: all methods may be called from any thread; one producer and
// one consumer are expected.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "core/common/status.h"
#include "core/mv/byte_source.h"

namespace slapse::server {

struct UploadQueueOptions {
  // Bytes buffered at most; a Write beyond this blocks until the reader drains.
  int64_t capacity_bytes = 4 << 20;
  // Total bytes one upload may send; more is RESOURCE_EXHAUSTED. 0 = no limit.
  int64_t max_total_bytes = 0;
  // Idle timeouts, enforced while the reader waits for bytes (0 = none):
  // no Start() within start_idle_timeout_ms of the queue's creation (the
  // session was created but its upload never began), or no bytes for
  // stall_timeout_ms once started (a stalled upload). Either closes the queue
  // with DEADLINE_EXCEEDED and a message naming the `serve` flag.
  int64_t start_idle_timeout_ms = 0;
  int64_t stall_timeout_ms = 0;
};

class UploadQueue {
 public:
  explicit UploadQueue(UploadQueueOptions options);

  // The upload began (its rpc arrived): the stall timeout applies from now.
  void Start();

  // Appends bytes, blocking while the buffer is full. Returns OK once queued;
  // RESOURCE_EXHAUSTED past max_total_bytes (the queue is then closed with
  // that status, so the reader fails too); the reason given to Close() if the
  // consumer closed the queue; CANCELLED if `cancelled` turns true while
  // waiting (polled every 50 ms).
  Status Write(std::string bytes, const std::function<bool()>& cancelled);
  // The producer is done: the reader sees end of stream after the buffered bytes.
  void Finish();
  // Ends the queue from either side: pending and future Writes return
  // `reason`, Read returns -1. Idempotent (the first reason wins).
  void Close(Status reason);

  // ByteSource semantics: blocks until bytes, end of stream (0) or Close (-1).
  int Read(uint8_t* buf, int size);
  // As Read, and returns -1 without closing the queue once `interrupt`
  // (polled every 50 ms while waiting) returns true.
  int Read(uint8_t* buf, int size, const std::function<bool()>& interrupt);

  int64_t total_bytes() const;
  // Why the queue was closed (OK while open or closed with OK).
  Status close_reason() const;

 private:
  using Clock = std::chrono::steady_clock;
  void CloseLocked(Status reason);
  // When the waiting reader gives up (Clock::time_point::max(): never).
  Clock::time_point IdleDeadlineLocked() const;
  Status IdleTimeoutErrorLocked() const;

  const UploadQueueOptions options_;
  mutable std::mutex mu_;
  std::condition_variable readable_, writable_;
  std::deque<std::string> chunks_;
  size_t head_offset_ = 0;  // bytes of chunks_.front() already read
  int64_t buffered_ = 0, total_ = 0;
  bool finished_ = false;
  bool closed_ = false;
  bool started_ = false;
  Clock::time_point created_, last_write_;
  Status close_reason_;
};

// A ByteSource reading from a shared UploadQueue (the reader owns this, the
// session and the rpc hold the queue).
class UploadByteSource : public ByteSource {
 public:
  explicit UploadByteSource(std::shared_ptr<UploadQueue> queue) : queue_(std::move(queue)) {}
  int Read(uint8_t* buf, int size) override { return queue_->Read(buf, size); }

 private:
  std::shared_ptr<UploadQueue> queue_;
};

}  // namespace slapse::server
