#include "client/lib/client.h"

#include <chrono>
#include <fstream>
#include <sstream>
#include <utility>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

#include "api/session_name.h"

namespace slapse::client {

Status FromGrpcStatus(const grpc::Status& s) {
  if (s.ok()) return Status::Ok();
  return Status(static_cast<StatusCode>(s.error_code()), s.error_message());
}

SlapseClient::SlapseClient(std::shared_ptr<v1::SlapseService::StubInterface> stub,
                           ClientOptions options)
    : stub_(std::move(stub)), options_(options) {}

namespace {

// The whole file, or "" if it cannot be read.
std::string ReadText(const std::string& path) {
  if (path.empty()) return "";
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return in ? ss.str() : "";
}

}  // namespace

Status ClientOptions::Check() const {
  if (!tls && (!tls_ca_file.empty() || !tls_cert_file.empty() || !tls_key_file.empty())) {
    return InvalidArgumentError("a CA or client certificate was given without --tls");
  }
  if (tls_cert_file.empty() != tls_key_file.empty()) {
    return InvalidArgumentError("a client certificate needs its key (--cert and --key)");
  }
  for (const auto& [flag, path] : {std::pair<std::string, std::string>{"--ca", tls_ca_file},
                                   {"--cert", tls_cert_file},
                                   {"--key", tls_key_file}}) {
    if (!path.empty() && ReadText(path).empty()) {
      return InvalidArgumentError(flag + " '" + path + "' cannot be read (or is empty)");
    }
  }
  for (char c : token) {
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f) {
      return InvalidArgumentError("the token has a space or control character in it");
    }
  }
  return Status::Ok();
}

std::unique_ptr<SlapseClient> SlapseClient::Connect(const std::string& target,
                                                    ClientOptions options) {
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  if (options.tls) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = ReadText(options.tls_ca_file);
    ssl.pem_cert_chain = ReadText(options.tls_cert_file);
    ssl.pem_private_key = ReadText(options.tls_key_file);
    credentials = grpc::SslCredentials(ssl);
  }
  auto channel = grpc::CreateChannel(target, credentials);
  return std::make_unique<SlapseClient>(v1::SlapseService::NewStub(channel), options);
}

void SlapseClient::PrepareContext(grpc::ClientContext* context, double timeout_s,
                                  const std::string& session) const {
  if (!options_.token.empty()) context->AddMetadata("authorization", "Bearer " + options_.token);
  // The routing header of a cluster's proxy (api/session_name.h).
  if (const std::string replica = api::SessionReplica(session); !replica.empty()) {
    context->AddMetadata(api::kReplicaHeader, replica);
  }
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
StatusOr<Response> SlapseClient::Unary(Method method, const Request& request,
                                       const std::string& session) {
  grpc::ClientContext context;
  PrepareContext(&context, options_.rpc_timeout_s, session);
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
                                                   request, name);
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
  PrepareContext(&context, options_.rpc_timeout_s, name);
  v1::DeleteSessionRequest request;
  request.set_name(name);
  v1::DeleteSessionResponse response;
  return FromGrpcStatus(stub_->DeleteSession(&context, request, &response));
}

StatusOr<v1::Session> SlapseClient::StopSession(const std::string& name) {
  v1::StopSessionRequest request;
  request.set_name(name);
  return Unary<v1::StopSessionRequest, v1::Session>(&v1::SlapseService::StubInterface::StopSession,
                                                    request, name);
}

StatusOr<v1::Trajectory> SlapseClient::GetTrajectoryPage(const v1::GetTrajectoryRequest& request) {
  return Unary<v1::GetTrajectoryRequest, v1::Trajectory>(
      &v1::SlapseService::StubInterface::GetTrajectory, request, request.name());
}

StatusOr<v1::PlaneMap> SlapseClient::GetPlaneMapPage(const v1::GetPlaneMapRequest& request) {
  return Unary<v1::GetPlaneMapRequest, v1::PlaneMap>(&v1::SlapseService::StubInterface::GetPlaneMap,
                                                     request, request.name());
}

StatusOr<v1::Trajectory> SlapseClient::GetTrajectory(const std::string& name) {
  v1::Trajectory out;
  bool first = true;
  Status s = ForEachTrajectoryPage(name, [&](v1::Trajectory& page) {
    if (first) {
      out = std::move(page);  // its name and last_sequence: every later page is at least as new
      first = false;
    } else {
      for (auto& p : *page.mutable_points()) *out.add_points() = std::move(p);
      out.set_metric(page.metric());
    }
    return true;
  });
  if (!s.ok()) return s;
  out.clear_next_page_token();
  return out;
}

Status SlapseClient::ForEachTrajectoryPage(const std::string& name,
                                           const std::function<bool(v1::Trajectory&)>& on_page) {
  v1::GetTrajectoryRequest request;
  request.set_name(name);
  request.set_page_size(options_.page_size);
  while (true) {
    auto page = GetTrajectoryPage(request);
    if (!page.ok()) return page.status();
    std::string next = page->next_page_token();  // before on_page, which may move the page
    if (!on_page(*page)) return Status(StatusCode::kCancelled, "stopped by the caller");
    if (next.empty()) return Status();
    request.set_page_token(std::move(next));
  }
}

StatusOr<v1::PlaneMap> SlapseClient::GetPlaneMap(const std::string& name) {
  v1::GetPlaneMapRequest request;
  request.set_name(name);
  request.set_page_size(options_.page_size);
  auto first = GetPlaneMapPage(request);
  if (!first.ok()) return first;
  v1::PlaneMap out = std::move(*first);
  while (!out.next_page_token().empty()) {
    request.set_page_token(out.next_page_token());
    auto page = GetPlaneMapPage(request);
    if (!page.ok()) return page.status();
    for (auto& p : *page->mutable_planes()) *out.add_planes() = std::move(p);
    out.set_metric(page->metric());
    out.set_next_page_token(page->next_page_token());
  }
  return out;
}

StatusOr<v1::Session> SlapseClient::Upload(const std::string& name,
                                           const std::function<bool(std::string*)>& next_chunk) {
  grpc::ClientContext context;
  PrepareContext(&context, options_.upload_timeout_s, name);
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
  PrepareContext(&context, options_.watch_timeout_s, name);
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
