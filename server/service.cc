#include "server/service.h"

#include "server/grpc_status.h"

namespace slapse::server {
namespace {

// Copies a StatusOr's value into `response` or returns its error.
template <typename T>
grpc::Status Reply(StatusOr<T> result, T* response) {
  if (!result.ok()) return ToGrpcStatus(result.status());
  *response = std::move(*result);
  return grpc::Status::OK;
}

// Events per WatchSession read, and how long one read waits for news.
constexpr size_t kWatchBatch = 256;
constexpr auto kWatchPoll = std::chrono::milliseconds(100);

}  // namespace

grpc::Status SlapseServiceImpl::CreateSession(grpc::ServerContext*,
                                              const v1::CreateSessionRequest* request,
                                              v1::Session* response) {
  return Reply(manager_->Create(request->session()), response);
}

grpc::Status SlapseServiceImpl::GetSession(grpc::ServerContext*,
                                           const v1::GetSessionRequest* request,
                                           v1::Session* response) {
  return Reply(manager_->Get(request->name()), response);
}

grpc::Status SlapseServiceImpl::ListSessions(grpc::ServerContext*,
                                             const v1::ListSessionsRequest* request,
                                             v1::ListSessionsResponse* response) {
  return Reply(manager_->List(*request), response);
}

grpc::Status SlapseServiceImpl::DeleteSession(grpc::ServerContext*,
                                              const v1::DeleteSessionRequest* request,
                                              v1::DeleteSessionResponse*) {
  return ToGrpcStatus(manager_->Delete(request->name()));
}

grpc::Status SlapseServiceImpl::StopSession(grpc::ServerContext*,
                                            const v1::StopSessionRequest* request,
                                            v1::Session* response) {
  return Reply(manager_->Stop(request->name()), response);
}

grpc::Status SlapseServiceImpl::UploadStream(grpc::ServerContext* context,
                                             grpc::ServerReader<v1::UploadChunk>* reader,
                                             v1::Session* response) {
  v1::UploadChunk first;
  if (!reader->Read(&first)) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "empty upload: the first message must name the session");
  }
  if (first.name().empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "the first upload message must name the session (sessions/{id})");
  }
  auto next = [reader](std::string* bytes) {
    v1::UploadChunk chunk;
    if (!reader->Read(&chunk)) return false;
    *bytes = std::move(*chunk.mutable_data());
    return true;
  };
  auto cancelled = [this, context] { return shutting_down_ || context->IsCancelled(); };
  return Reply(manager_->Upload(first.name(), std::move(*first.mutable_data()), next, cancelled),
               response);
}

grpc::Status SlapseServiceImpl::WatchSession(grpc::ServerContext* context,
                                             const v1::WatchSessionRequest* request,
                                             grpc::ServerWriter<v1::SessionEvent>* writer) {
  auto log = manager_->Events(request->name());
  if (!log.ok()) return ToGrpcStatus(log.status());
  uint64_t cursor = request->after_sequence();
  std::vector<v1::SessionEvent> events;
  for (;;) {
    if (context->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "cancelled");
    // At shutdown the sessions end STOPPED first, so watchers drain to that
    // final event and end here (OK) without a special case.
    events.clear();
    bool ended = false;
    Status s = (*log)->Read(cursor, kWatchBatch, std::chrono::steady_clock::now() + kWatchPoll,
                            &events, &ended);
    if (!s.ok()) return ToGrpcStatus(s);
    for (const v1::SessionEvent& e : events) {
      // A blocked Write holds only this watcher: the pipeline appends to the
      // ring and never waits for watchers.
      if (!writer->Write(e)) return grpc::Status(grpc::StatusCode::CANCELLED, "client went away");
      cursor = e.sequence();
    }
    if (ended) {
      // Suspended at shutdown (persistent store): the session goes on after
      // the restart.
      auto now = manager_->Get(request->name());
      if (shutting_down_ && now.ok() && !IsTerminal(now->state())) {
        return grpc::Status(grpc::StatusCode::UNAVAILABLE,
                            "the server is shutting down; the session resumes when it restarts: "
                            "watch again after sequence " +
                                std::to_string(cursor));
      }
      return grpc::Status::OK;
    }
  }
}

grpc::Status SlapseServiceImpl::GetTrajectory(grpc::ServerContext*,
                                              const v1::GetTrajectoryRequest* request,
                                              v1::Trajectory* response) {
  return Reply(manager_->GetTrajectory(*request), response);
}

grpc::Status SlapseServiceImpl::GetPlaneMap(grpc::ServerContext*,
                                            const v1::GetPlaneMapRequest* request,
                                            v1::PlaneMap* response) {
  return Reply(manager_->GetPlaneMap(*request), response);
}

}  // namespace slapse::server
