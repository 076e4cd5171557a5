#include "server/service.h"

#include <algorithm>
#include <future>

#include "api/list_query.h"
#include "api/session_name.h"
#include "api/validate.h"
#include "server/grpc_status.h"

namespace slapse::server {
namespace {

// An error as it may leave the server: its message masked.
grpc::Status Error(const Status& s) {
  return ToGrpcStatus(Status(s.code(), api::RedactText(s.message())));
}

// What a response may show: secrets masked.
void Redact(v1::Session* s) { api::RedactSession(s); }
void Redact(v1::ListSessionsResponse* r) {
  for (v1::Session& s : *r->mutable_sessions()) api::RedactSession(&s);
}
void Redact(v1::Trajectory*) {}
void Redact(v1::PlaneMap*) {}

// Copies a StatusOr's value into `response` (masked) or returns its error.
template <typename T>
grpc::Status Reply(StatusOr<T> result, T* response) {
  if (!result.ok()) return Error(result.status());
  *response = std::move(*result);
  Redact(response);
  return grpc::Status::OK;
}

// The value of metadata `key` sent by the client, "" if none.
std::string MetadataValue(const grpc::ServerContext& context, const char* key) {
  auto it = context.client_metadata().find(key);
  if (it == context.client_metadata().end()) return "";
  return std::string(it->second.data(), it->second.size());
}

// Events per WatchSession read, and how long one read waits for news.
constexpr size_t kWatchBatch = 256;
constexpr auto kWatchPoll = std::chrono::milliseconds(100);

}  // namespace

StatusOr<Caller> SlapseServiceImpl::Authorize(const grpc::ServerContext& context,
                                              const std::string& rpc, bool read) const {
  if (auth_ == nullptr) return Caller{};
  auto caller = auth_->Authenticate(context);
  if (!caller.ok()) return caller.status();
  if (!read) SLAPSE_RETURN_IF_ERROR(Authenticator::CheckMayWrite(*caller, rpc));
  return caller;
}

Status SlapseServiceImpl::CheckOwner(const std::string& name, const Caller& caller) const {
  if (auth_ == nullptr || !auth_->enabled()) return Status::Ok();
  auto s = manager_->Get(name);
  if (!s.ok()) return s.status();
  if (s->tenant() != caller.tenant) return SessionNotFoundError(name);
  return Status::Ok();
}

// The caller of the rpc or its error, then the ownership of `name`.
#define SLAPSE_AUTHORIZE(caller, rpc, read)     \
  auto caller = Authorize(*context, rpc, read); \
  if (!caller.ok()) return Error(caller.status())
#define SLAPSE_CHECK_OWNER(name, caller) \
  if (Status owner = CheckOwner(name, *caller); !owner.ok()) return Error(owner)

grpc::Status SlapseServiceImpl::CreateSession(grpc::ServerContext* context,
                                              const v1::CreateSessionRequest* request,
                                              v1::Session* response) {
  SLAPSE_AUTHORIZE(caller, "CreateSession", false);
  v1::Session session = request->session();
  session.set_tenant(caller->tenant);  // output only: the caller's, whatever was sent
  return Reply(manager_->Create(session), response);
}

grpc::Status SlapseServiceImpl::GetSession(grpc::ServerContext* context,
                                           const v1::GetSessionRequest* request,
                                           v1::Session* response) {
  SLAPSE_AUTHORIZE(caller, "GetSession", true);
  SLAPSE_CHECK_OWNER(request->name(), caller);
  return Reply(manager_->Get(request->name()), response);
}

grpc::Status SlapseServiceImpl::ListSessions(grpc::ServerContext* context,
                                             const v1::ListSessionsRequest* request,
                                             v1::ListSessionsResponse* response) {
  SLAPSE_AUTHORIZE(caller, "ListSessions", true);
  const bool filter = auth_ != nullptr && auth_->enabled();
  const std::string* tenant = filter ? &caller->tenant : nullptr;
  if (!replica_id_.empty()) context->AddInitialMetadata(api::kReplicaHeader, replica_id_);
  if (peers_ == nullptr || MetadataValue(*context, api::kFanoutHeader) == api::kFanoutLocal) {
    return Reply(manager_->List(*request, tenant), response);
  }
  return ListCluster(context, *request, tenant, response);
}

grpc::Status SlapseServiceImpl::ListCluster(grpc::ServerContext* context,
                                            const v1::ListSessionsRequest& request,
                                            const std::string* tenant,
                                            v1::ListSessionsResponse* response) {
  // A bad query fails here, before any peer is asked.
  if (auto checked = manager_->List(request, tenant); !checked.ok()) return Error(checked.status());
  // The peers work while this replica collects its own matching sessions.
  auto remote = std::async(std::launch::async, [&] {
    return peers_->Collect(request, MetadataValue(*context, "authorization"));
  });
  v1::ListSessionsRequest mine;
  mine.set_filter(request.filter());
  mine.set_state_filter(request.state_filter());
  mine.set_page_size(api::kMaxListPageSize);
  std::vector<v1::Session> all;
  do {
    auto page = manager_->List(mine, tenant);
    if (!page.ok()) return Error(page.status());
    for (v1::Session& s : *page->mutable_sessions()) all.push_back(std::move(s));
    mine.set_page_token(page->next_page_token());
  } while (!mine.page_token().empty());
  PeerFanout::Result peers = remote.get();
  for (v1::Session& s : peers.sessions) all.push_back(std::move(s));
  // The cluster's creation order: create_time, then the replica; within one
  // replica its own order (stable sort), which is its creation order also
  // for equal timestamps. order_by keeps this order for ties.
  std::stable_sort(all.begin(), all.end(), [](const v1::Session& a, const v1::Session& b) {
    const auto& ta = a.create_time();
    const auto& tb = b.create_time();
    if (ta.seconds() != tb.seconds()) return ta.seconds() < tb.seconds();
    if (ta.nanos() != tb.nanos()) return ta.nanos() < tb.nanos();
    return api::SessionReplica(a.name()) < api::SessionReplica(b.name());
  });
  auto page = api::ApplyListQuery(std::move(all), request);
  if (!page.ok()) return Error(page.status());
  for (std::string& u : peers.unreachable) page->add_unreachable_peers(api::RedactText(u));
  return Reply(std::move(page), response);
}

grpc::Status SlapseServiceImpl::DeleteSession(grpc::ServerContext* context,
                                              const v1::DeleteSessionRequest* request,
                                              v1::DeleteSessionResponse*) {
  SLAPSE_AUTHORIZE(caller, "DeleteSession", false);
  SLAPSE_CHECK_OWNER(request->name(), caller);
  const Status s = manager_->Delete(request->name());
  return s.ok() ? grpc::Status::OK : Error(s);
}

grpc::Status SlapseServiceImpl::StopSession(grpc::ServerContext* context,
                                            const v1::StopSessionRequest* request,
                                            v1::Session* response) {
  SLAPSE_AUTHORIZE(caller, "StopSession", false);
  SLAPSE_CHECK_OWNER(request->name(), caller);
  return Reply(manager_->Stop(request->name()), response);
}

grpc::Status SlapseServiceImpl::UploadStream(grpc::ServerContext* context,
                                             grpc::ServerReader<v1::UploadChunk>* reader,
                                             v1::Session* response) {
  SLAPSE_AUTHORIZE(caller, "UploadStream", false);
  v1::UploadChunk first;
  if (!reader->Read(&first)) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "empty upload: the first message must name the session");
  }
  if (first.name().empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "the first upload message must name the session (sessions/{id})");
  }
  SLAPSE_CHECK_OWNER(first.name(), caller);
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
  SLAPSE_AUTHORIZE(caller, "WatchSession", true);
  SLAPSE_CHECK_OWNER(request->name(), caller);
  auto log = manager_->Events(request->name());
  if (!log.ok()) return Error(log.status());
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
    if (!s.ok()) return Error(s);
    for (v1::SessionEvent& e : events) {
      api::RedactEvent(&e);
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

grpc::Status SlapseServiceImpl::GetTrajectory(grpc::ServerContext* context,
                                              const v1::GetTrajectoryRequest* request,
                                              v1::Trajectory* response) {
  SLAPSE_AUTHORIZE(caller, "GetTrajectory", true);
  SLAPSE_CHECK_OWNER(request->name(), caller);
  return Reply(manager_->GetTrajectory(*request), response);
}

grpc::Status SlapseServiceImpl::GetPlaneMap(grpc::ServerContext* context,
                                            const v1::GetPlaneMapRequest* request,
                                            v1::PlaneMap* response) {
  SLAPSE_AUTHORIZE(caller, "GetPlaneMap", true);
  SLAPSE_CHECK_OWNER(request->name(), caller);
  return Reply(manager_->GetPlaneMap(*request), response);
}

}  // namespace slapse::server
