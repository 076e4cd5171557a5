#include "server/peers.h"

#include <grpcpp/grpcpp.h>

#include <fstream>
#include <future>
#include <sstream>

#include "api/list_query.h"
#include "api/session_name.h"

namespace slapse::server {
namespace {

std::string ReadText(const std::string& path) {
  if (path.empty()) return "";
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

std::string Trim(const std::string& s) {
  const size_t b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return "";
  return s.substr(b, s.find_last_not_of(" \t") - b + 1);
}

}  // namespace

std::vector<std::string> SplitPeerList(const std::string& list) {
  std::vector<std::string> out;
  std::stringstream in(list);
  std::string item;
  while (std::getline(in, item, ',')) {
    if (!Trim(item).empty()) out.push_back(Trim(item));
  }
  return out;
}

Status PeerOptions::Check() const {
  for (const std::string& a : addresses) {
    const size_t colon = a.rfind(':');
    if (a.empty() || colon == std::string::npos || colon == 0 || colon + 1 == a.size() ||
        a.find_first_not_of("0123456789", colon + 1) != std::string::npos) {
      return InvalidArgumentError("peer '" + a + "' is not host:port (serve --peers)");
    }
  }
  if (!(timeout_s > 0)) return InvalidArgumentError("the peer timeout must be > 0 s");
  return Status::Ok();
}

PeerFanout::PeerFanout(PeerOptions options) : options_(std::move(options)) {
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  if (options_.tls) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = ReadText(options_.tls_ca_file);
    ssl.pem_cert_chain = ReadText(options_.tls_cert_file);
    ssl.pem_private_key = ReadText(options_.tls_key_file);
    credentials = grpc::SslCredentials(ssl);
  }
  // A peer that was down is asked again within a second of its return: a
  // channel in reconnect backoff fails calls at once, and gRPC's default
  // backoff grows to two minutes.
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 200);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 200);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 1000);
  for (const std::string& address : options_.addresses) {
    peers_.push_back({address, v1::SlapseService::NewStub(
                                   grpc::CreateCustomChannel(address, credentials, args))});
  }
}

Status PeerFanout::CollectOne(const Peer& peer, const v1::ListSessionsRequest& request,
                              const std::string& authorization, std::vector<v1::Session>* sessions,
                              bool* is_self) const {
  // The filter travels; order and paging are the merge's (all pages here).
  v1::ListSessionsRequest page_request;
  page_request.set_filter(request.filter());
  page_request.set_state_filter(request.state_filter());
  page_request.set_page_size(api::kMaxListPageSize);
  const auto deadline = std::chrono::system_clock::now() +
                        std::chrono::duration_cast<std::chrono::system_clock::duration>(
                            std::chrono::duration<double>(options_.timeout_s));
  *is_self = false;
  do {
    grpc::ClientContext context;
    context.set_deadline(deadline);
    context.AddMetadata(api::kFanoutHeader, api::kFanoutLocal);
    if (!authorization.empty()) context.AddMetadata("authorization", authorization);
    v1::ListSessionsResponse page;
    grpc::Status s = peer.stub->ListSessions(&context, page_request, &page);
    if (!s.ok()) return Status(static_cast<StatusCode>(s.error_code()), s.error_message());
    const auto& meta = context.GetServerInitialMetadata();
    auto it = meta.find(api::kReplicaHeader);
    if (it != meta.end() && !options_.self_replica.empty() &&
        std::string(it->second.data(), it->second.size()) == options_.self_replica) {
      *is_self = true;
      sessions->clear();
      return Status::Ok();
    }
    for (v1::Session& session : *page.mutable_sessions()) sessions->push_back(std::move(session));
    page_request.set_page_token(page.next_page_token());
  } while (!page_request.page_token().empty());
  return Status::Ok();
}

PeerFanout::Result PeerFanout::Collect(const v1::ListSessionsRequest& request,
                                       const std::string& authorization) const {
  struct One {
    Status status;
    std::vector<v1::Session> sessions;
    bool is_self = false;
  };
  std::vector<std::future<One>> pending;
  for (const Peer& peer : peers_) {
    pending.push_back(std::async(std::launch::async, [&] {
      One one;
      one.status = CollectOne(peer, request, authorization, &one.sessions, &one.is_self);
      return one;
    }));
  }
  Result result;
  for (size_t i = 0; i < pending.size(); ++i) {
    One one = pending[i].get();
    if (!one.status.ok()) {
      result.unreachable.push_back(peers_[i].address + ": " + one.status.ToString());
      continue;
    }
    for (v1::Session& s : one.sessions) result.sessions.push_back(std::move(s));
  }
  return result;
}

}  // namespace slapse::server
