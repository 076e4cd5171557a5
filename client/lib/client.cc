#include "client/lib/client.h"

#include <chrono>
#include <fstream>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

namespace slapse::client {

Status FromGrpcStatus(const grpc::Status& s) {
  if (s.ok()) return Status::Ok();
  return Status(static_cast<StatusCode>(s.error_code()), s.error_message());
}

SlapseClient::SlapseClient(std::shared_ptr<v1::SlapseService::StubInterface> stub,
                           ClientOptions options)
    : stub_(std::move(stub)), options_(options) {}

std::unique_ptr<SlapseClient> SlapseClient::Connect(const std::string& target,
                                                    ClientOptions options) {
  auto channel = grpc::CreateChannel(target, grpc::InsecureChannelCredentials());
  return std::make_unique<SlapseClient>(v1::SlapseService::NewStub(channel), options);
}

void SlapseClient::SetDeadline(grpc::ClientContext* context, double timeout_s) const {
  if (timeout_s <= 0) return;
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::duration_cast<std::chrono::system_clock::duration>(
                            std::chrono::duration<double>(timeout_s)));
}

namespace {

template <typename Response>
StatusOr<Response> Result(const grpc::Status& s, Response response) {
  if (!s.ok()) return FromGrpcStatus(s);
  return response;
}

}  // namespace

template <typename Request, typename Response, typename Method>
StatusOr<Response> SlapseClient::Unary(Method method, const Request& request) {
  grpc::ClientContext context;
  SetDeadline(&context, options_.rpc_timeout_s);
  Response response;
  const grpc::Status s = ((*stub_).*method)(&context, request, &response);
  return Result(s, std::move(response));
}

StatusOr<v1::Session> SlapseClient::CreateSession(const v1::Session& session) {
  v1::CreateSessionRequest request;
  *request.mutable_session() = session;
  return Unary<v1::CreateSessionRequest, v1::Session>(
      &v1::SlapseService::StubInterface::CreateSession, request);
}

StatusOr<v1::Session> SlapseClient::GetSession(const std::string& name) {
  v1::GetSessionRequest request;
  request.set_name(name);
  return Unary<v1::GetSessionRequest, v1::Session>(&v1::SlapseService::StubInterface::GetSession,
                                                   request);
}

StatusOr<v1::ListSessionsResponse> SlapseClient::ListSessions(int page_size,
                                                              const std::string& page_token,
                                                              v1::Session::State state) {
  v1::ListSessionsRequest request;
  request.set_page_size(page_size);
  request.set_page_token(page_token);
  request.set_state_filter(state);
  return ListSessions(request);
}

StatusOr<v1::ListSessionsResponse> SlapseClient::ListSessions(
    const v1::ListSessionsRequest& request) {
  return Unary<v1::ListSessionsRequest, v1::ListSessionsResponse>(
      &v1::SlapseService::StubInterface::ListSessions, request);
}

Status SlapseClient::DeleteSession(const std::string& name) {
  grpc::ClientContext context;
  SetDeadline(&context, options_.rpc_timeout_s);
  v1::DeleteSessionRequest request;
  request.set_name(name);
  v1::DeleteSessionResponse response;
  return FromGrpcStatus(stub_->DeleteSession(&context, request, &response));
}

StatusOr<v1::Session> SlapseClient::StopSession(const std::string& name) {
  v1::StopSessionRequest request;
  request.set_name(name);
  return Unary<v1::StopSessionRequest, v1::Session>(&v1::SlapseService::StubInterface::StopSession,
                                                    request);
}

StatusOr<v1::Trajectory> SlapseClient::GetTrajectory(const std::string& name) {
  v1::GetTrajectoryRequest request;
  request.set_name(name);
  return Unary<v1::GetTrajectoryRequest, v1::Trajectory>(
      &v1::SlapseService::StubInterface::GetTrajectory, request);
}

StatusOr<v1::PlaneMap> SlapseClient::GetPlaneMap(const std::string& name) {
  v1::GetPlaneMapRequest request;
  request.set_name(name);
  return Unary<v1::GetPlaneMapRequest, v1::PlaneMap>(&v1::SlapseService::StubInterface::GetPlaneMap,
                                                     request);
}

StatusOr<v1::Session> SlapseClient::Upload(const std::string& name,
                                           const std::function<bool(std::string*)>& next_chunk) {
  grpc::ClientContext context;
  SetDeadline(&context, options_.upload_timeout_s);
  v1::Session response;
  std::unique_ptr<grpc::ClientWriterInterface<v1::UploadChunk>> writer =
      stub_->UploadStream(&context, &response);
  v1::UploadChunk msg;
  msg.set_name(name);  // the first message names the session
  bool more = true;
  do {
    more = next_chunk(msg.mutable_data());
    // A failed Write means the server ended the call early; Finish() says why.
    if (!writer->Write(msg)) break;
    msg.clear_name();
  } while (more);
  writer->WritesDone();
  grpc::Status s = writer->Finish();
  return Result(s, std::move(response));
}

StatusOr<v1::Session> SlapseClient::UploadBytes(const std::string& name, const std::string& bytes) {
  const size_t chunk = options_.upload_chunk_bytes > 0 ? options_.upload_chunk_bytes : 1 << 18;
  size_t pos = 0;
  return Upload(name, [&](std::string* out) {
    *out = bytes.substr(pos, chunk);
    pos += chunk;
    return pos < bytes.size();
  });
}

StatusOr<v1::Session> SlapseClient::UploadFile(const std::string& name, const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return NotFoundError("cannot read '" + path + "'");
  const size_t chunk = options_.upload_chunk_bytes > 0 ? options_.upload_chunk_bytes : 1 << 18;
  bool read_error = false;
  auto result = Upload(name, [&](std::string* out) {
    out->resize(chunk);
    in.read(out->data(), static_cast<std::streamsize>(chunk));
    out->resize(static_cast<size_t>(in.gcount()));
    if (in.bad()) read_error = true;
    return in.good();
  });
  if (read_error) return DataLossError("error reading '" + path + "'");
  return result;
}

Status SlapseClient::Watch(const std::string& name, uint64_t after_sequence,
                           const std::function<bool(const v1::SessionEvent&)>& on_event) {
  grpc::ClientContext context;
  SetDeadline(&context, options_.watch_timeout_s);
  v1::WatchSessionRequest request;
  request.set_name(name);
  request.set_after_sequence(after_sequence);
  std::unique_ptr<grpc::ClientReaderInterface<v1::SessionEvent>> reader =
      stub_->WatchSession(&context, request);
  v1::SessionEvent event;
  while (reader->Read(&event)) {
    if (!on_event(event)) {
      context.TryCancel();
      while (reader->Read(&event)) {
      }
      (void)reader->Finish();
      return CancelledError("watch stopped by the caller");
    }
  }
  return FromGrpcStatus(reader->Finish());
}

}  // namespace slapse::client
