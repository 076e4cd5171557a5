// The session manager's rpc side: create (validate, admit, queue), find,
// list, stop, delete, feed an upload and read snapshots. A session's state
// machine is server/session.h, its run server/session_runner.h, its sources
// server/ingest_source.h, the pool server/worker_pool.h.
#include "server/session_manager.h"

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <cstdlib>

#include "api/validate.h"
#include "server/ingest_source.h"
#include "server/session_runner.h"

namespace slapse::server {

using google::protobuf::util::TimeUtil;

SessionManager::SessionManager(SessionManagerOptions options)
    : options_(options), pool_(options_.max_sessions) {}

SessionManager::~SessionManager() { Shutdown(); }

int SessionManager::ActiveCountLocked() const {
  int n = 0;
  for (const auto& [id, s] : sessions_) {
    std::lock_guard<std::mutex> lock(s->mu);
    n += !IsTerminal(s->proto.state());
  }
  return n;
}

StatusOr<v1::Session> SessionManager::Create(const v1::Session& request) {
  SLAPSE_RETURN_IF_ERROR(api::ValidateSession(request));
  if (request.has_rtp_sdp()) SLAPSE_RETURN_IF_ERROR(CheckRtpPortsFree(request.rtp_sdp().sdp()));
  std::shared_ptr<Session> s;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (shutting_down_) return UnavailableError("the server is shutting down");
    const int active = ActiveCountLocked();
    if (active >= options_.max_sessions) {
      return ResourceExhaustedError(
          "the server is at capacity: " + std::to_string(active) + " of " +
          std::to_string(options_.max_sessions) +
          " sessions active; stop or delete one, or retry later (serve --max-sessions)");
    }
    const uint64_t id = next_id_++;
    UploadQueueOptions q;
    q.capacity_bytes = options_.upload_buffer_bytes;
    q.max_total_bytes = options_.max_upload_bytes;
    q.start_idle_timeout_ms = options_.create_idle_timeout_ms;
    q.stall_timeout_ms = options_.upload_stall_timeout_ms;
    s = std::make_shared<Session>("sessions/" + std::to_string(id), options_.event_ring_capacity,
                                  q);
    s->proto = request;
    s->proto.set_name(s->name);
    s->proto.clear_stats();
    s->proto.clear_error();
    s->proto.clear_ingest_url();
    s->proto.clear_stream_report();
    if (request.has_rtsp_push()) {
      auto url = RtspPushIngestUrl(options_.rtsp_push_host, request.rtsp_push().path());
      if (!url.ok()) return url.status();
      s->proto.set_ingest_url(*url);
    }
    s->proto.set_state(v1::Session::STATE_UNSPECIFIED);
    *s->proto.mutable_create_time() = TimeUtil::GetCurrentTime();
    s->Transition(v1::Session::CREATED, Status::Ok(), "created; waiting for the stream");
    sessions_[id] = s;
    // Queued under mu_, so a Shutdown after this still runs (and ends) it.
    pool_.Submit([s] { SessionRunner(s).Run(); });
  }
  return s->Snapshot();
}

StatusOr<std::shared_ptr<Session>> SessionManager::Find(const std::string& name) const {
  const std::string prefix = "sessions/";
  uint64_t id = 0;
  bool ok = name.size() > prefix.size() && name.compare(0, prefix.size(), prefix) == 0 &&
            name.size() - prefix.size() <= 19;
  for (size_t i = prefix.size(); ok && i < name.size(); ++i) {
    ok = name[i] >= '0' && name[i] <= '9';
    id = id * 10 + (name[i] - '0');
  }
  if (!ok) return InvalidArgumentError("'" + name + "' is not a session name (sessions/{id})");
  std::lock_guard<std::mutex> lock(mu_);
  auto it = sessions_.find(id);
  if (it == sessions_.end()) return NotFoundError("no session '" + name + "' on this server");
  return it->second;
}

StatusOr<v1::Session> SessionManager::Get(const std::string& name) const {
  auto s = Find(name);
  if (!s.ok()) return s.status();
  return (*s)->Snapshot();
}

StatusOr<v1::ListSessionsResponse> SessionManager::List(
    const v1::ListSessionsRequest& request) const {
  SLAPSE_RETURN_IF_ERROR(api::ValidateListRequest(request));
  const size_t page_size =
      request.page_size() == 0 ? 50 : std::min<size_t>(request.page_size(), 1000);
  uint64_t after = 0;
  if (!request.page_token().empty()) {
    char* end = nullptr;
    after = std::strtoull(request.page_token().c_str(), &end, 10);
    if (end == nullptr || *end != '\0') return InvalidArgumentError("bad page_token");
  }
  std::vector<std::shared_ptr<Session>> candidates;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto it = sessions_.upper_bound(after); it != sessions_.end(); ++it) {
      candidates.push_back(it->second);
    }
  }
  v1::ListSessionsResponse out;
  for (size_t i = 0; i < candidates.size(); ++i) {
    v1::Session snap = candidates[i]->Snapshot();
    if (request.state_filter() != v1::Session::STATE_UNSPECIFIED &&
        snap.state() != request.state_filter()) {
      continue;
    }
    if (static_cast<size_t>(out.sessions_size()) == page_size) {
      // More follow: the token is the id of the last session returned.
      const std::string& last = out.sessions(out.sessions_size() - 1).name();
      out.set_next_page_token(last.substr(std::string("sessions/").size()));
      break;
    }
    *out.add_sessions() = std::move(snap);
  }
  return out;
}

StatusOr<v1::Session> SessionManager::Stop(const std::string& name) {
  auto s = Find(name);
  if (!s.ok()) return s.status();
  (*s)->Stop("stopped by StopSession");
  return (*s)->Snapshot();
}

Status SessionManager::Delete(const std::string& name) {
  auto s = Find(name);
  if (!s.ok()) return s.status();
  (*s)->Stop("deleted");
  std::lock_guard<std::mutex> lock(mu_);
  for (auto it = sessions_.begin(); it != sessions_.end(); ++it) {
    if (it->second == *s) {
      sessions_.erase(it);
      break;
    }
  }
  return Status::Ok();
}

StatusOr<v1::Session> SessionManager::Upload(const std::string& name, std::string first_bytes,
                                             const std::function<bool(std::string*)>& next,
                                             const std::function<bool()>& cancelled) {
  auto found = Find(name);
  if (!found.ok()) return found.status();
  Session* s = found->get();
  {
    std::lock_guard<std::mutex> lock(s->mu);
    if (!s->proto.has_upload()) {
      return FailedPreconditionError(name + " is not an upload session");
    }
    if (IsTerminal(s->proto.state())) {
      return FailedPreconditionError(name + " is " + v1::Session::State_Name(s->proto.state()));
    }
    if (s->upload_started) {
      return FailedPreconditionError(name + " already received its upload (one per session)");
    }
    s->upload_started = true;
    s->upload->Start();
    s->TransitionLocked(v1::Session::RUNNING, Status::Ok(), "upload started");
  }
  Status st = s->upload->Write(std::move(first_bytes), cancelled);
  std::string chunk;
  while (st.ok() && next(&chunk)) st = s->upload->Write(std::move(chunk), cancelled);
  // The client's stream ended: a half-close finishes the upload, a cancelled
  // rpc (the client went away or cancelled) does not.
  if ((st.ok() || st.code() == StatusCode::kCancelled) && cancelled()) {
    st = CancelledError(
        "the upload ended before the client finished it (the client "
        "disconnected or cancelled after " +
        std::to_string(s->upload->total_bytes()) + " bytes)");
  }
  if (!st.ok()) {
    if (st.code() == StatusCode::kCancelled || st.code() == StatusCode::kResourceExhausted) {
      {
        std::lock_guard<std::mutex> lock(s->mu);
        if (s->ingest_error.ok()) s->ingest_error = st;
      }
      s->upload->Close(st);
    }
    // A session that ended on its own reports its own error.
    v1::Session snap = s->Snapshot();
    if (snap.state() == v1::Session::FAILED && snap.error().code() != 0) {
      return Status(static_cast<StatusCode>(snap.error().code()), snap.error().message());
    }
    return st;
  }
  s->upload->Finish();
  return s->Snapshot();
}

StatusOr<std::shared_ptr<EventLog>> SessionManager::Events(const std::string& name) const {
  auto s = Find(name);
  if (!s.ok()) return s.status();
  return (*s)->events;
}

StatusOr<v1::Trajectory> SessionManager::GetTrajectory(const std::string& name) const {
  auto found = Find(name);
  if (!found.ok()) return found.status();
  const Session& s = **found;
  v1::Trajectory out;
  std::lock_guard<std::mutex> lock(s.mu);
  out.set_name(s.name);
  out.set_metric(s.metric);
  for (const auto& p : s.trajectory) *out.add_points() = p;
  out.set_last_sequence(s.events->last_sequence());
  return out;
}

StatusOr<v1::PlaneMap> SessionManager::GetPlaneMap(const std::string& name) const {
  auto found = Find(name);
  if (!found.ok()) return found.status();
  const Session& s = **found;
  v1::PlaneMap out;
  std::lock_guard<std::mutex> lock(s.mu);
  out.set_name(s.name);
  out.set_metric(s.metric);
  for (const auto& [id, p] : s.planes) *out.add_planes() = p;
  out.set_last_sequence(s.events->last_sequence());
  return out;
}

void SessionManager::Shutdown() {
  std::vector<std::shared_ptr<Session>> all;
  {
    std::lock_guard<std::mutex> lock(mu_);
    shutting_down_ = true;
    for (const auto& [id, s] : sessions_) all.push_back(s);
  }
  for (const auto& s : all) s->Stop("the server is shutting down");
  // The queued sessions run too: stopped, they end at once.
  pool_.Shutdown();
}

}  // namespace slapse::server
