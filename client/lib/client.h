// SlapseClient: a thin, blocking C++ client of slapse.v1.SlapseService,
// written against the generated StubInterface (tests may pass a mock stub).
//
//   auto client = SlapseClient::Connect("localhost:50051");
//   auto session = client->CreateUploadSession(intrinsics, {});
//   client->UploadFile(session->name(), "drive.ts");
//   client->Watch(session->name(), 0, [](const v1::SessionEvent& e) { ...; return true; });
//
// Every rpc carries a deadline (ClientOptions). Errors come back as
// slapse::Status with the server's code and message.
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
};

// grpc::Status -> slapse::Status (codes are numerically equal).
Status FromGrpcStatus(const grpc::Status& s);

class SlapseClient {
 public:
  SlapseClient(std::shared_ptr<v1::SlapseService::StubInterface> stub, ClientOptions options = {});
  // An insecure channel to `target` ("host:port").
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
  StatusOr<v1::Trajectory> GetTrajectory(const std::string& name);
  StatusOr<v1::PlaneMap> GetPlaneMap(const std::string& name);

  // Sends `bytes` / the file at `path` in chunks as the session's stream.
  StatusOr<v1::Session> UploadBytes(const std::string& name, const std::string& bytes);
  StatusOr<v1::Session> UploadFile(const std::string& name, const std::string& path);

  // Streams events after `after_sequence` into `on_event` until the session
  // ends (OK), `on_event` returns false (CANCELLED), the deadline passes or
  // the server fails the stream (its status, e.g. OUT_OF_RANGE).
  Status Watch(const std::string& name, uint64_t after_sequence,
               const std::function<bool(const v1::SessionEvent&)>& on_event);

 private:
  // Streams chunks from `next_chunk` (fills one, returns false after the last).
  StatusOr<v1::Session> Upload(const std::string& name,
                               const std::function<bool(std::string*)>& next_chunk);
  void SetDeadline(grpc::ClientContext* context, double timeout_s) const;
  // One unary rpc with the client's deadline: (stub->*method)(ctx, request, &response).
  template <typename Request, typename Response, typename Method>
  StatusOr<Response> Unary(Method method, const Request& request);

  std::shared_ptr<v1::SlapseService::StubInterface> stub_;
  ClientOptions options_;
};

}  // namespace slapse::client
