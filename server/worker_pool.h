// WorkerPool: a fixed set of threads that run queued jobs in FIFO order.
//
// The session manager gives each session one job for its whole life (stream
// reads block), with as many threads as sessions may be active, so a job
// never waits for a thread behind a running session.
//
// Thread-safety: Submit and Shutdown may be called from any thread.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace slapse::server {

class WorkerPool {
 public:
  // Starts max(1, threads) threads.
  explicit WorkerPool(int threads);
  // Shutdown().
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Queues `job` for the next free thread.
  void Submit(std::function<void()> job);
  // Runs the jobs still queued, then joins the threads. Idempotent.
  void Shutdown();

 private:
  void Loop();

  std::mutex mu_;
  std::condition_variable work_ready_;
  std::deque<std::function<void()>> queue_;
  std::vector<std::thread> threads_;
  bool shutting_down_ = false;
};

}  // namespace slapse::server
