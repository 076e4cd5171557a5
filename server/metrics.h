// The server's metrics, in Prometheus' text exposition format (served on
// /metrics by server/http_server.h; names in docs/DEPLOY.md).
//
// Three sources, read at scrape time:
//   sessions  read from SessionManager::List snapshots on every scrape (no
//             bookkeeping of their own): sessions by state, FAILED sessions by
//             error code, and per session its frames, anchor pairs, tracked
//             pairs (poses), planes, fps, lag and reconnects
//   rpcs      counted by a gRPC server interceptor (RpcMetricsInterceptorFactory):
//             calls by method and status code (the errors by code), calls in
//             flight by method, and the open WatchSession streams (watchers)
//   stages    StageTimer, observed by the session runners of the process:
//             seconds per frame in each stage, as histograms
//   store     the store's size (SessionManager::StoreBytes, Store::SizeBytes),
//             read at scrape time
//
//   ServerMetrics metrics(&manager);
//   builder.experimental().SetInterceptorCreators(metrics.TakeInterceptorFactories());
//   std::string text = metrics.Exposition();
//
// Thread-safety: every method may be called from any thread.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/support/server_interceptor.h>
#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/registry.h>

#include "server/session_manager.h"

namespace slapse::server {

// The content type of Exposition()'s text.
inline constexpr const char* kPrometheusContentType = "text/plain; version=0.0.4; charset=utf-8";

// Where a session's time per frame goes (slapse_stage_seconds{stage=...}).
enum class Stage {
  kRead,      // waiting for and decoding the next frame (MvReader::Next; network waits included)
  kPipeline,  // the pipeline's step on the frame (Pipeline::Push)
  kPublish,   // statistics, snapshots and events for watchers (SessionRunner::Publish)
};

// Times one stage from construction to Done() (or destruction), once.
class StageTimer {
 public:
  explicit StageTimer(Stage stage) : stage_(stage), start_(std::chrono::steady_clock::now()) {}
  ~StageTimer() { Done(); }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;
  void Done();

 private:
  Stage stage_;
  std::chrono::steady_clock::time_point start_;
  bool done_ = false;
};

class ServerMetrics {
 public:
  // `sessions` must outlive this object.
  explicit ServerMetrics(const SessionManager* sessions);
  ~ServerMetrics();

  // The interceptor that counts this server's rpcs, for ServerBuilder.
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>>
  InterceptorFactories();

  // Every metric, as Prometheus' text format 0.0.4.
  std::string Exposition() const;

  // Called by the interceptor at the start and the end of every call.
  void RpcStarted(const std::string& method);
  void RpcFinished(const std::string& method, int grpc_code);

 private:
  struct RpcFamilies;
  const SessionManager* sessions_;
  std::shared_ptr<prometheus::Registry> registry_;
  std::unique_ptr<RpcFamilies> rpc_;
};

}  // namespace slapse::server
