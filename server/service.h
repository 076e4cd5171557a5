// The gRPC face of SessionManager: slapse.v1.SlapseService over the sync API.
//
// Thread-safety: gRPC calls the handlers concurrently; all state lives in the
// (thread-safe) SessionManager.
#pragma once

#include <atomic>
#include <chrono>

#include "server/session_manager.h"
#include "slapse/v1/slapse.grpc.pb.h"

namespace slapse::server {

class SlapseServiceImpl final : public v1::SlapseService::Service {
 public:
  // `manager` must outlive the service.
  explicit SlapseServiceImpl(SessionManager* manager) : manager_(manager) {}

  // Makes blocked UploadStream calls fail soon (CANCELLED).
  void BeginShutdown() { shutting_down_ = true; }

  grpc::Status CreateSession(grpc::ServerContext* context, const v1::CreateSessionRequest* request,
                             v1::Session* response) override;
  grpc::Status GetSession(grpc::ServerContext* context, const v1::GetSessionRequest* request,
                          v1::Session* response) override;
  grpc::Status ListSessions(grpc::ServerContext* context, const v1::ListSessionsRequest* request,
                            v1::ListSessionsResponse* response) override;
  grpc::Status DeleteSession(grpc::ServerContext* context, const v1::DeleteSessionRequest* request,
                             v1::DeleteSessionResponse* response) override;
  grpc::Status StopSession(grpc::ServerContext* context, const v1::StopSessionRequest* request,
                           v1::Session* response) override;
  grpc::Status UploadStream(grpc::ServerContext* context,
                            grpc::ServerReader<v1::UploadChunk>* reader,
                            v1::Session* response) override;
  grpc::Status WatchSession(grpc::ServerContext* context, const v1::WatchSessionRequest* request,
                            grpc::ServerWriter<v1::SessionEvent>* writer) override;
  grpc::Status GetTrajectory(grpc::ServerContext* context, const v1::GetTrajectoryRequest* request,
                             v1::Trajectory* response) override;
  grpc::Status GetPlaneMap(grpc::ServerContext* context, const v1::GetPlaneMapRequest* request,
                           v1::PlaneMap* response) override;

 private:
  SessionManager* manager_;
  std::atomic<bool> shutting_down_{false};
};

}  // namespace slapse::server
