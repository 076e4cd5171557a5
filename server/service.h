// The gRPC face of SessionManager: slapse.v1.SlapseService over the sync API.
//
// Every rpc first asks the Authenticator (server/auth.h) who calls
// (UNAUTHENTICATED otherwise) and whether it may change things
// (PERMISSION_DENIED for a read-only token); a session of another tenant is
// NOT_FOUND, word for word as an unknown one, and ListSessions leaves it out.
// Everything that leaves (sessions, events, error messages) goes through
// api::RedactSession / RedactEvent / RedactText first.
//
// Thread-safety: gRPC calls the handlers concurrently; all state lives in the
// (thread-safe) SessionManager.
#pragma once

#include <atomic>
#include <chrono>

#include "server/auth.h"
#include "server/peers.h"
#include "server/session_manager.h"
#include "slapse/v1/slapse.grpc.pb.h"

namespace slapse::server {

class SlapseServiceImpl final : public v1::SlapseService::Service {
 public:
  // `manager` and `auth` must outlive the service; a null `auth` lets every
  // caller in as the single tenant "".
  explicit SlapseServiceImpl(SessionManager* manager, Authenticator* auth = nullptr)
      : manager_(manager), auth_(auth) {}

  // In a cluster: this replica's id (sent in ListSessions' initial
  // metadata as api::kReplicaHeader) and its peers, which ListSessions asks
  // too (server/peers.h); `peers` null = this server's sessions only.
  // Call before serving; `peers` must outlive the service.
  void SetCluster(const std::string& replica_id, const PeerFanout* peers) {
    replica_id_ = replica_id;
    peers_ = peers;
  }

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
  // The caller of `context`, which may `rpc` (a write unless `read`).
  StatusOr<Caller> Authorize(const grpc::ServerContext& context, const std::string& rpc,
                             bool read) const;
  // NOT_FOUND (as SessionManager says for an unknown name) unless `caller`
  // owns session `name`; a malformed or unknown name gives the manager's error.
  Status CheckOwner(const std::string& name, const Caller& caller) const;

  // ListSessions over this replica and its peers (SetCluster).
  grpc::Status ListCluster(grpc::ServerContext* context, const v1::ListSessionsRequest& request,
                           const std::string* tenant, v1::ListSessionsResponse* response);

  SessionManager* manager_;
  Authenticator* auth_;
  std::string replica_id_;
  const PeerFanout* peers_ = nullptr;
  std::atomic<bool> shutting_down_{false};
};

}  // namespace slapse::server
