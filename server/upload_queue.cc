#include "server/upload_queue.h"

#include <algorithm>
#include <chrono>
#include <cstring>

namespace slapse::server {

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
  if (closed_) return;
  closed_ = true;
  close_reason_ = reason.ok() ? CancelledError("the session ended") : std::move(reason);
  chunks_.clear();
  buffered_ = 0;
  readable_.notify_all();
  writable_.notify_all();
}

int UploadQueue::Read(uint8_t* buf, int size) {
  std::unique_lock<std::mutex> lock(mu_);
  readable_.wait(lock, [&] { return closed_ || finished_ || !chunks_.empty(); });
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
