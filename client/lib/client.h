// SlapseClient: a thin, blocking C++ client of slapse.v1.SlapseService,
// written against the generated StubInterface (tests may pass a mock stub).
//
//   auto client = SlapseClient::Connect("localhost:50051");
//   auto session = client->CreateUploadSession(intrinsics, {});
//   client->UploadFile(session->name(), "drive.ts");
//   client->Watch(session->name(), 0, [](const v1::SessionEvent& e) { ...; return true; });
//
// Every rpc carries a deadline (ClientOptions). Errors come back as
// slapse::Status with the server's code and message. Every call about one
// session whose name carries its owner replica ("sessions/<replica>-<id>",
// api/session_name.h) sends the header "x-slapse-replica: <replica>", by
// which a cluster's proxy routes it to that replica (docs/DEPLOY.md).
// Thread-safety: a SlapseClient may be used from several threads at once.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "core/common/status.h"
#include "slapse/v1/slapse.grpc.pb.h"

namespace slapse::client {

struct ClientOptions {
  // Deadline of each unary rpc, seconds.
  double rpc_timeout_s = 10.0;
  // Deadline of a whole UploadStream, seconds.
  double upload_timeout_s = 600.0;
  // Deadline of a whole WatchSession, seconds; 0 = none (watch until the session ends).
  double watch_timeout_s = 0.0;
  // Bytes per UploadChunk.
  int upload_chunk_bytes = 256 << 10;
  // Points (planes) per GetTrajectory (GetPlaneMap) page when fetching a
  // whole snapshot: 20 000 points are ~2 MB, under gRPC's 4 MB message cap.
  int page_size = 20000;
  // TLS on/off. tls_ca_file: PEM bundle of the CA that signed the server's
  // certificate (empty: the system's roots). tls_cert_file + tls_key_file:
  // this client's certificate and key (PEM) for a server that wants mTLS.
  bool tls = false;
  std::string tls_ca_file;
  std::string tls_cert_file;
  std::string tls_key_file;
  // Bearer token sent with every rpc as "authorization: Bearer <token>";
  // empty: none. (gRPC's call credentials would refuse a plain-text channel,
  // which a loopback server may use, so it is plain metadata.)
  std::string token;

  // INVALID_ARGUMENT for TLS files without --tls, a certificate without its
  // key (or the reverse), an unreadable file, or a token with a space or a
  // control character in it.
  Status Check() const;
};

// grpc::Status -> slapse::Status (codes are numerically equal).
Status FromGrpcStatus(const grpc::Status& s);

class SlapseClient {
 public:
  SlapseClient(std::shared_ptr<v1::SlapseService::StubInterface> stub, ClientOptions options = {});
  // A channel to `target` ("host:port"): TLS with `options`' files when
  // options.tls, else plain text. Call options.Check() first: a file that
  // cannot be read here leaves the channel without it, which fails closed.
  static std::unique_ptr<SlapseClient> Connect(const std::string& target,
                                               ClientOptions options = {});

  StatusOr<v1::Session> CreateSession(const v1::Session& session);
  StatusOr<v1::Session> GetSession(const std::string& name);
  // One page; state = STATE_UNSPECIFIED for all.
  StatusOr<v1::ListSessionsResponse> ListSessions(int page_size, const std::string& page_token,
                                                  v1::Session::State state);
  // One page of a query with filter / order_by (api/list_query.h).
  StatusOr<v1::ListSessionsResponse> ListSessions(const v1::ListSessionsRequest& request);
  Status DeleteSession(const std::string& name);
  StatusOr<v1::Session> StopSession(const std::string& name);
  // The whole snapshot, fetched page by page (any session length).
  StatusOr<v1::Trajectory> GetTrajectory(const std::string& name);
  // The same pages handed to `on_page` one at a time as they arrive, so a
  // caller that writes them out holds one page (options.page_size points),
  // not the session. Stops at the last page (OK), at the first failed rpc
  // (its status) or when `on_page` returns false (CANCELLED). The page is
  // `on_page`'s to keep: it may move from it.
  Status ForEachTrajectoryPage(const std::string& name,
                               const std::function<bool(v1::Trajectory&)>& on_page);
  StatusOr<v1::PlaneMap> GetPlaneMap(const std::string& name);
  // One page (page_size, page_token, time range as the request says).
  StatusOr<v1::Trajectory> GetTrajectoryPage(const v1::GetTrajectoryRequest& request);
  StatusOr<v1::PlaneMap> GetPlaneMapPage(const v1::GetPlaneMapRequest& request);

  // Sends `bytes` / the file at `path` in chunks as the session's stream.
  StatusOr<v1::Session> UploadBytes(const std::string& name, const std::string& bytes);
  StatusOr<v1::Session> UploadFile(const std::string& name, const std::string& path);
  // Streams chunks from `next_chunk` (fills one, returns false after the
  // last) as the session's stream: bytes as they come, e.g. from a pipe.
  StatusOr<v1::Session> Upload(const std::string& name,
                               const std::function<bool(std::string*)>& next_chunk);

  // Streams events after `after_sequence` into `on_event` until the session
  // ends (OK), `on_event` returns false (CANCELLED), the deadline passes or
  // the server fails the stream (its status, e.g. OUT_OF_RANGE).
  Status Watch(const std::string& name, uint64_t after_sequence,
               const std::function<bool(const v1::SessionEvent&)>& on_event);

 private:
  // The deadline (none for timeout_s <= 0), the bearer token and, for a call
  // about `session` whose name carries its replica, the routing header
  // api::kReplicaHeader of an rpc.
  void PrepareContext(grpc::ClientContext* context, double timeout_s,
                      const std::string& session = "") const;
  // One unary rpc with the client's deadline: (stub->*method)(ctx, request, &response).
  template <typename Request, typename Response, typename Method>
  StatusOr<Response> Unary(Method method, const Request& request, const std::string& session = "");

  std::shared_ptr<v1::SlapseService::StubInterface> stub_;
  ClientOptions options_;
};

}  // namespace slapse::client
