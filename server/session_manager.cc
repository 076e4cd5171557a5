// The session manager's rpc side: create (validate, admit, queue), find,
// list, stop, delete, feed an upload and read snapshots. A session's state
// machine is server/session.h, its run server/session_runner.h, its sources
// server/ingest_source.h, the pool server/worker_pool.h.
#include "server/session_manager.h"

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <random>

#include "api/list_query.h"
#include "api/session_name.h"
#include "api/validate.h"
#include "server/ingest_source.h"
#include "server/session_runner.h"

namespace slapse::server {

using google::protobuf::util::TimeUtil;

Status SessionNotFoundError(const std::string& name) {
  return NotFoundError("no session '" + name + "' on this server");
}

SessionManager::SessionManager(SessionManagerOptions options)
    : options_(options), pool_(options_.max_sessions) {}

SessionManager::~SessionManager() { Shutdown(); }

namespace {

// 128 random bits as 26 base32 characters (RFC 4648 alphabet, lower case).
std::string RandomSessionId() {
  static constexpr char kAlphabet[] = "abcdefghijklmnopqrstuvwxyz234567";
  std::random_device rd;  // /dev/urandom
  std::array<uint32_t, 4> words{rd(), rd(), rd(), rd()};
  std::string id;
  int bits = 0;
  uint64_t acc = 0;
  for (uint32_t w : words) {
    acc = (acc << 32) | w;
    bits += 32;
    while (bits >= 5) {
      id += kAlphabet[(acc >> (bits - 5)) & 31];
      bits -= 5;
    }
  }
  id += kAlphabet[(acc << (5 - bits)) & 31];  // the last 3 bits
  return id;
}

constexpr const char* kSessionPrefix = "sessions/";

}  // namespace

UploadQueueOptions SessionManager::QueueOptions() const {
  UploadQueueOptions q;
  q.capacity_bytes = options_.upload_buffer_bytes;
  q.max_total_bytes = options_.max_upload_bytes;
  q.start_idle_timeout_ms = options_.create_idle_timeout_ms;
  q.stall_timeout_ms = options_.upload_stall_timeout_ms;
  return q;
}

Status SessionManager::Open() {
  auto store = Store::Open(options_.data_dir);
  if (!store.ok()) return store.status();
  store_ = std::move(*store);
  auto key = LoadOrCreateRtspIngestKey(options_.data_dir);
  if (!key.ok()) return key.status();
  RtspIngestOptions rtsp;
  rtsp.host = options_.rtsp_push_host;
  rtsp.url_host = options_.rtsp_url_host;
  rtsp.port = options_.rtsp_port;
  rtsp.key = std::move(*key);
  rtsp.buffer_bytes = options_.upload_buffer_bytes;
  rtsp.rtp_ports = options_.rtp_ports;
  auto ingest = RtspIngest::Start(rtsp);
  if (!ingest.ok()) return ingest.status();
  rtsp_ = std::move(*ingest);
  auto stored = store_->LoadSessions();
  if (!stored.ok()) return stored.status();
  for (StoredSession& s : *stored) Restore(std::move(s));
  if (options_.retention_ttl_s > 0 || options_.retention_max_store_bytes > 0) {
    retention_ = std::thread([this] { RetentionLoop(); });  // server/retention.cc
  }
  return Status::Ok();
}

void SessionManager::Restore(StoredSession stored) {
  const v1::Session::State state = stored.proto.state();
  auto s =
      std::make_shared<Session>(stored.proto.name(), options_.event_ring_capacity, QueueOptions(),
                                store_, stored.ordinal, stored.last_sequence, IsTerminal(state));
  s->proto = std::move(stored.proto);
  s->points = stored.points;
  s->metric = stored.metric;
  {
    std::lock_guard<std::mutex> lock(mu_);
    sessions_[stored.ordinal] = s;
    ordinals_[s->name] = stored.ordinal;
  }
  if (IsTerminal(state)) return;
  if (s->proto.has_upload() && state == v1::Session::RUNNING) {
    s->Transition(v1::Session::FAILED,
                  Status(StatusCode::kAborted,
                         "the server restarted during the upload (after " +
                             std::to_string(s->proto.stats().frames()) +
                             " frames were processed; their results are kept); upload the "
                             "stream again to a new session"));
    return;
  }
  if (s->proto.has_rtsp_push()) {
    // Mounted again on this run's RTSP port (the same credentials).
    auto url = rtsp_->Mount(s->name, s->proto.rtsp_push().path());
    if (url.ok()) s->proto.set_ingest_url(*url);
  }
  if (!s->proto.has_upload()) {
    s->segment = stored.max_segment + 1;
    s->resumed_down_s =
        TimeUtil::DurationToNanoseconds(TimeUtil::GetCurrentTime() - s->proto.update_time()) * 1e-9;
    if (s->proto.stats().frames() > 0) {
      s->resumed_last_index =
          std::max<int64_t>(stored.max_anchor_index, s->proto.stats().frames() - 1);
    }
    if (state == v1::Session::RUNNING) {
      s->Transition(v1::Session::CREATED, Status::Ok(),
                    std::string("the server restarted; ") +
                        (s->proto.has_rtsp_pull() ? "reconnecting to the camera"
                                                  : "waiting for the sender again") +
                        " (poses from now on are segment " + std::to_string(s->segment) +
                        ", in a new world frame)");
    }
  }
  pool_.Submit([s, keep = options_.final_poses_in_memory, probe = options_.reader_probe_bytes] {
    SessionRunner(s, keep, probe).Run();
  });
}

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
  if (request.has_rtp_sdp()) {
    SLAPSE_RETURN_IF_ERROR(CheckRtpPortsInRange(request.rtp_sdp().sdp(), options_.rtp_ports));
    SLAPSE_RETURN_IF_ERROR(CheckRtpPortsFree(request.rtp_sdp().sdp()));
  }
  std::shared_ptr<Session> s;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (shutting_down_) return UnavailableError("the server is shutting down");
    if (store_ == nullptr) return UnavailableError("the session store is not open");
    const int active = ActiveCountLocked();
    if (active >= options_.max_sessions) {
      return ResourceExhaustedError(
          "the server is at capacity: " + std::to_string(active) + " of " +
          std::to_string(options_.max_sessions) +
          " sessions active; stop or delete one, or retry later (serve --max-sessions)");
    }
    v1::Session proto = request;
    proto.set_name(api::MakeSessionName(options_.replica_id, RandomSessionId()));
    proto.clear_stats();
    proto.clear_error();
    proto.clear_ingest_url();
    proto.clear_publish_credentials();  // output only; never stored
    proto.clear_stream_report();
    if (request.has_rtsp_push()) {
      if (rtsp_ == nullptr) return UnavailableError("the RTSP ingest port is not open");
      auto url = rtsp_->Mount(proto.name(), request.rtsp_push().path());
      if (!url.ok()) return url.status();
      proto.set_ingest_url(*url);
    }
    proto.set_state(v1::Session::STATE_UNSPECIFIED);
    *proto.mutable_create_time() = TimeUtil::GetCurrentTime();
    *proto.mutable_update_time() = proto.create_time();
    auto ordinal = store_->AddSession(proto);
    if (!ordinal.ok()) {
      if (request.has_rtsp_push()) RtspIngest::Unmount(proto.name());
      return ordinal.status();
    }
    s = std::make_shared<Session>(proto.name(), options_.event_ring_capacity, QueueOptions(),
                                  store_, *ordinal);
    s->proto = std::move(proto);
    s->Transition(v1::Session::CREATED, Status::Ok(), "created; waiting for the stream");
    sessions_[*ordinal] = s;
    ordinals_[s->name] = *ordinal;
    // Queued under mu_, so a Shutdown after this still runs (and ends) it.
    pool_.Submit([s, keep = options_.final_poses_in_memory, probe = options_.reader_probe_bytes] {
      SessionRunner(s, keep, probe).Run();
    });
  }
  v1::Session created = s->Snapshot();
  // The publish credentials: in this response only, never stored.
  if (request.has_rtsp_push()) {
    const RtspPublishCredentials c = rtsp_->Credentials(created.name());
    created.mutable_publish_credentials()->set_username(c.username);
    created.mutable_publish_credentials()->set_password(c.password);
  }
  return created;
}

int SessionManager::rtsp_port() const { return rtsp_ == nullptr ? 0 : rtsp_->port(); }

int64_t SessionManager::StoreBytes() const {
  std::shared_ptr<Store> store;
  {
    std::lock_guard<std::mutex> lock(mu_);
    store = store_;
  }
  return store == nullptr ? 0 : store->SizeBytes();
}

StatusOr<std::shared_ptr<Session>> SessionManager::Find(const std::string& name) const {
  const std::string prefix = kSessionPrefix;
  bool ok = name.size() > prefix.size() && name.size() <= prefix.size() + 64 &&
            name.compare(0, prefix.size(), prefix) == 0;
  for (size_t i = prefix.size(); ok && i < name.size(); ++i) {
    ok = (name[i] >= '0' && name[i] <= '9') || (name[i] >= 'a' && name[i] <= 'z') || name[i] == '-';
  }
  if (!ok) return InvalidArgumentError("'" + name + "' is not a session name (sessions/{id})");
  if (const std::string owner = api::SessionReplica(name);
      !owner.empty() && !options_.replica_id.empty() && owner != options_.replica_id) {
    return NotFoundError("no session '" + name + "' on this server: it belongs to replica '" +
                         owner + "' and this is '" + options_.replica_id + "' (route the call by " +
                         "its " + api::kReplicaHeader + " header; docs/DEPLOY.md)");
  }
  std::lock_guard<std::mutex> lock(mu_);
  auto it = ordinals_.find(name);
  if (it == ordinals_.end()) return SessionNotFoundError(name);
  return sessions_.at(it->second);
}

StatusOr<v1::Session> SessionManager::Get(const std::string& name) const {
  auto s = Find(name);
  if (!s.ok()) return s.status();
  return (*s)->Snapshot();
}

StatusOr<v1::ListSessionsResponse> SessionManager::List(const v1::ListSessionsRequest& request,
                                                        const std::string* tenant) const {
  std::vector<std::shared_ptr<Session>> all;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (const auto& [id, s] : sessions_) all.push_back(s);
  }
  // The caller's sessions; the query (filter, order, page) is api/list_query.h's.
  std::vector<v1::Session> snapshots;
  snapshots.reserve(all.size());
  for (const auto& s : all) {
    v1::Session snap = s->Snapshot();
    if (tenant != nullptr && snap.tenant() != *tenant) continue;
    snapshots.push_back(std::move(snap));
  }
  return api::ApplyListQuery(std::move(snapshots), request);
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
  {
    std::lock_guard<std::mutex> lock(mu_);
    sessions_.erase((*s)->ordinal);
    ordinals_.erase((*s)->name);
  }
  return store_->DeleteSession((*s)->ordinal);
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

StatusOr<std::shared_ptr<FrameOverlays>> SessionManager::Overlays(const std::string& name) const {
  auto s = Find(name);
  if (!s.ok()) return s.status();
  return (*s)->overlays;
}

namespace {

// Points in one unpaged GetTrajectory (below the 4 MiB message limit), and
// the most one page may hold.
constexpr size_t kMaxUnpagedPoints = 40000;
constexpr size_t kMaxPageSize = 100000;

// The page size asked for (0: everything up to `unpaged`, plus one to see
// whether there is more) and the page token's number (-1: none).
Status ParsePaging(int32_t page_size, const std::string& token, size_t unpaged, size_t* max,
                   int64_t* after) {
  if (page_size < 0) {
    return InvalidArgumentError("page_size must be >= 0, got " + std::to_string(page_size));
  }
  *max = page_size == 0 ? unpaged : std::min<size_t>(page_size, kMaxPageSize);
  if (token.empty()) return Status::Ok();
  char* end = nullptr;
  *after = std::strtoll(token.c_str(), &end, 10);
  if (end == nullptr || *end != '\0' || *after < 0) {
    return InvalidArgumentError("bad page_token '" + token +
                                "': pass the next_page_token of the previous page");
  }
  return Status::Ok();
}

Status CheckNotExpired(const Session& s) {
  if (s.proto.state() != v1::Session::EXPIRED) return Status::Ok();
  return FailedPreconditionError(s.name + " is EXPIRED: " + s.proto.state_message());
}

}  // namespace

StatusOr<v1::Trajectory> SessionManager::GetTrajectory(const v1::GetTrajectoryRequest& r) const {
  size_t max = 0;
  int64_t after = 0;
  SLAPSE_RETURN_IF_ERROR(
      ParsePaging(r.page_size(), r.page_token(), kMaxUnpagedPoints, &max, &after));
  if (!std::isfinite(r.start_time_s()) || !std::isfinite(r.end_time_s()) ||
      (r.end_time_s() > 0 && r.end_time_s() <= r.start_time_s())) {
    return InvalidArgumentError(
        "the time range [start_time_s, end_time_s) must be finite and "
        "non-empty (end_time_s 0: no upper bound)");
  }
  auto found = Find(r.name());
  if (!found.ok()) return found.status();
  const Session& s = **found;
  v1::Trajectory out;
  {
    std::lock_guard<std::mutex> lock(s.mu);
    SLAPSE_RETURN_IF_ERROR(CheckNotExpired(s));
    out.set_name(s.name);
    out.set_metric(s.metric);
  }
  // The sequence first: the points read are at least as new as it says.
  out.set_last_sequence(s.events->last_sequence());
  std::vector<v1::Trajectory::Point> points;
  std::vector<int64_t> numbers;
  const double start_s = r.start_time_s() > 0 ? r.start_time_s() : -1e300;
  SLAPSE_RETURN_IF_ERROR(
      store_->ReadPoints(s.ordinal, after, start_s, r.end_time_s(), max + 1, &points, &numbers));
  if (points.size() > max) {
    if (r.page_size() == 0) {
      return ResourceExhaustedError(
          s.name + " has more than " + std::to_string(kMaxUnpagedPoints) +
          " trajectory points, more than one message holds: request pages (page_size, "
          "page_token) or a time range; `slapse export` pages by itself");
    }
    points.pop_back();
    out.set_next_page_token(std::to_string(numbers[max - 1]));
  }
  for (auto& p : points) *out.add_points() = std::move(p);
  return out;
}

StatusOr<v1::PlaneMap> SessionManager::GetPlaneMap(const v1::GetPlaneMapRequest& r) const {
  size_t max = 0;
  int64_t after = -1;
  SLAPSE_RETURN_IF_ERROR(
      ParsePaging(r.page_size(), r.page_token(), kMaxUnpagedPoints, &max, &after));
  auto found = Find(r.name());
  if (!found.ok()) return found.status();
  const Session& s = **found;
  v1::PlaneMap out;
  {
    std::lock_guard<std::mutex> lock(s.mu);
    SLAPSE_RETURN_IF_ERROR(CheckNotExpired(s));
    out.set_name(s.name);
    out.set_metric(s.metric);
  }
  out.set_last_sequence(s.events->last_sequence());
  std::vector<v1::PlaneMap::Plane> planes;
  int64_t last_key = after;
  SLAPSE_RETURN_IF_ERROR(store_->ReadPlanes(s.ordinal, after, max + 1, &planes, &last_key));
  if (planes.size() > max) {
    if (r.page_size() == 0) {
      return ResourceExhaustedError(s.name + " has more than " + std::to_string(kMaxUnpagedPoints) +
                                    " planes: request pages (page_size, page_token)");
    }
    planes.pop_back();
    const v1::PlaneMap::Plane& last = planes.back();
    out.set_next_page_token(std::to_string((int64_t{last.segment()} << 31) + last.track_id()));
  }
  for (auto& p : planes) *out.add_planes() = std::move(p);
  return out;
}

void SessionManager::Shutdown() {
  std::vector<std::shared_ptr<Session>> all;
  {
    std::lock_guard<std::mutex> lock(mu_);
    shutting_down_ = true;
    for (const auto& [id, s] : sessions_) all.push_back(s);
  }
  retention_cv_.notify_all();
  if (retention_.joinable()) retention_.join();
  // A persistent store: the active sessions stay active in it and resume
  // after the restart; in memory they end STOPPED.
  const bool persistent = options_.data_dir != kInMemoryDataDir;
  for (const auto& s : all) {
    if (persistent) {
      s->Suspend();
    } else {
      s->Stop("the server is shutting down");
    }
  }
  // The queued sessions run too: stopped, they end at once.
  pool_.Shutdown();
}

}  // namespace slapse::server
