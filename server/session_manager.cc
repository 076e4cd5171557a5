#include "server/session_manager.h"

#include <google/protobuf/util/time_util.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <optional>
#include <set>

#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"

namespace slapse::server {
namespace {

using google::protobuf::util::TimeUtil;
using Clock = std::chrono::steady_clock;

bool IsTerminal(v1::Session::State s) {
  return s == v1::Session::FINISHED || s == v1::Session::FAILED || s == v1::Session::STOPPED;
}

bool Finite(double v) { return std::isfinite(v); }

// Network sources: defaults of RtspPull / RtspPush / RtpSdp start_timeout_ms
// and receive_timeout_ms (0 in the request), and the largest SDP accepted.
constexpr int kDefaultStartTimeoutMs = 60000;
constexpr int kDefaultReceiveTimeoutMs = 5000;
constexpr size_t kMaxSdpBytes = 64 << 10;
// RTSP pull: ReconnectPolicy defaults (0 in the request) and bounds.
constexpr int kDefaultReconnectIntervalMs = 1000;
constexpr double kDefaultBackoffMultiplier = 2.0;
constexpr int kDefaultMaxReconnectIntervalMs = 30000;
constexpr int kMaxReconnectAttempts = 1000000;
constexpr int kMaxReconnectIntervalMs = 3600000;
constexpr size_t kMaxRtspUrlChars = 2048;

// The wall clock to the nanosecond (TimeUtil::GetCurrentTime of protobuf 3.21
// has whole seconds only).
google::protobuf::Timestamp PreciseNow() {
  return TimeUtil::NanosecondsToTimestamp(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                              std::chrono::system_clock::now().time_since_epoch())
                                              .count());
}

Status ValidateTimeouts(int start_ms, int receive_ms, const std::string& what) {
  if (start_ms < 0 || receive_ms < 0) {
    return InvalidArgumentError(what +
                                ".start_timeout_ms and receive_timeout_ms must be >= 0 "
                                "(0 = the default)");
  }
  return Status::Ok();
}

Status ValidateRtspPath(const std::string& path) {
  bool ok = !path.empty() && path.size() <= 256 && path[0] != '/';
  for (char c : path) {
    ok = ok && (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-' ||
                c == '/');
  }
  if (!ok) {
    return InvalidArgumentError("rtsp_push.path '" + path +
                                "' is not a path: 1 to 256 of [A-Za-z0-9._-/], no leading '/'");
  }
  return Status::Ok();
}

// The URL with any user:password@ replaced by ***@, for messages.
std::string RedactUrl(const std::string& url) {
  const size_t scheme_end = url.find("://");
  if (scheme_end == std::string::npos) return url;
  const size_t auth = scheme_end + 3;
  const size_t auth_end = std::min(url.find_first_of("/?#", auth), url.size());
  const size_t at = url.rfind('@', auth_end == 0 ? 0 : auth_end - 1);
  if (at == std::string::npos || at < auth) return url;
  return url.substr(0, auth) + "***" + url.substr(at);
}

// rtsp:// or rtsps:// with a host (a name, an IPv4 address or a bracketed
// IPv6 address) and an optional port; no spaces or control characters.
Status ValidateRtspUrl(const std::string& url) {
  auto bad = [&](const std::string& why) {
    return InvalidArgumentError("rtsp_pull.url '" + RedactUrl(url) + "' " + why +
                                "; want rtsp://[user:password@]host[:port]/path or rtsps://...");
  };
  if (url.empty()) return InvalidArgumentError("rtsp_pull.url is required, e.g. rtsp://cam:554/1");
  if (url.size() > kMaxRtspUrlChars) return bad("is longer than 2048 characters");
  for (char c : url) {
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f) {
      return bad("contains a space or control character");
    }
  }
  const size_t scheme_end = url.find("://");
  std::string scheme = scheme_end == std::string::npos ? "" : url.substr(0, scheme_end);
  for (char& c : scheme) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (scheme != "rtsp" && scheme != "rtsps") return bad("does not start with rtsp:// or rtsps://");
  const size_t auth = scheme_end + 3;
  const size_t auth_end = std::min(url.find_first_of("/?#", auth), url.size());
  std::string hostport = url.substr(auth, auth_end - auth);
  const size_t at = hostport.rfind('@');
  if (at != std::string::npos) hostport = hostport.substr(at + 1);
  std::string host, port;
  if (!hostport.empty() && hostport[0] == '[') {
    const size_t close = hostport.find(']');
    if (close == std::string::npos) return bad("has an IPv6 host without its closing ']'");
    host = hostport.substr(1, close - 1);
    const std::string rest = hostport.substr(close + 1);
    if (!rest.empty() && rest[0] != ':') return bad("has characters after the IPv6 host");
    if (!rest.empty()) port = rest.substr(1);
    for (char c : host) {
      if (!std::isxdigit(static_cast<unsigned char>(c)) && c != ':' && c != '.') {
        return bad("has an IPv6 host with characters other than hex digits, ':' and '.'");
      }
    }
  } else {
    const size_t colon = hostport.find(':');
    host = hostport.substr(0, colon);
    if (colon != std::string::npos) port = hostport.substr(colon + 1);
    for (char c : host) {
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-' && c != '_') {
        return bad("has a host with characters other than letters, digits, '.', '-' and '_'");
      }
    }
  }
  if (host.empty()) return bad("has no host");
  if (!port.empty() || hostport.back() == ':') {
    bool digits = !port.empty() && port.size() <= 5;
    for (char c : port) digits = digits && std::isdigit(static_cast<unsigned char>(c));
    const long n = digits ? std::strtol(port.c_str(), nullptr, 10) : 0;
    if (n < 1 || n > 65535) return bad("has a port that is not 1..65535");
  }
  return Status::Ok();
}

Status ValidateReconnectPolicy(const v1::ReconnectPolicy& p) {
  auto bad = [](const std::string& why) {
    return InvalidArgumentError("rtsp_pull.reconnect." + why);
  };
  if (p.max_attempts() < 0 || p.max_attempts() > kMaxReconnectAttempts) {
    return bad("max_attempts must be in [0, 1000000] (0 = no reconnect), got " +
               std::to_string(p.max_attempts()));
  }
  if (p.initial_interval_ms() < 0 || p.initial_interval_ms() > kMaxReconnectIntervalMs) {
    return bad("initial_interval_ms must be in [0, 3600000] ms (0 = 1000), got " +
               std::to_string(p.initial_interval_ms()));
  }
  if (p.max_interval_ms() < 0 || p.max_interval_ms() > kMaxReconnectIntervalMs) {
    return bad("max_interval_ms must be in [0, 3600000] ms (0 = 30000), got " +
               std::to_string(p.max_interval_ms()));
  }
  const double m = p.backoff_multiplier();
  if (!Finite(m) || (m != 0 && (m < 1 || m > 100))) {
    return bad("backoff_multiplier must be in [1, 100] (0 = 2), got " + std::to_string(m));
  }
  if (p.max_interval_ms() > 0 && p.max_interval_ms() < p.initial_interval_ms()) {
    return bad("max_interval_ms (" + std::to_string(p.max_interval_ms()) +
               ") must be >= initial_interval_ms (" + std::to_string(p.initial_interval_ms()) +
               ")");
  }
  return Status::Ok();
}

// The wait before retry `attempt` (1, 2, ...) of an outage, ms.
int ReconnectDelayMs(const v1::ReconnectPolicy& p, int attempt) {
  const double initial =
      p.initial_interval_ms() > 0 ? p.initial_interval_ms() : kDefaultReconnectIntervalMs;
  const double factor =
      p.backoff_multiplier() > 0 ? p.backoff_multiplier() : kDefaultBackoffMultiplier;
  const double cap = p.max_interval_ms() > 0
                         ? p.max_interval_ms()
                         : std::max<double>(kDefaultMaxReconnectIntervalMs, initial);
  double delay = initial;
  for (int k = 1; k < attempt && delay < cap; ++k) delay *= factor;
  return static_cast<int>(std::min(delay, cap));
}

// A light syntax check (RFC 4566): "v=0" first, every line "<letter>=...",
// a c= line and an m=video line with a port. FFmpeg's SDP parser accepts
// almost anything, so this is what turns a malformed SDP into INVALID_ARGUMENT.
Status ValidateSdp(const std::string& sdp) {
  auto bad = [](const std::string& why) { return InvalidArgumentError("rtp_sdp.sdp: " + why); };
  if (sdp.empty()) return bad("required (the session description text)");
  if (sdp.size() > kMaxSdpBytes) return bad("longer than 64 KiB");
  if (sdp.find('\0') != std::string::npos) return bad("contains a NUL byte");
  bool first = true, has_c = false, has_video = false;
  size_t pos = 0;
  while (pos < sdp.size()) {
    size_t eol = sdp.find('\n', pos);
    if (eol == std::string::npos) eol = sdp.size();
    std::string line = sdp.substr(pos, eol - pos);
    pos = eol + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    if (line.size() < 2 || line[1] != '=' || !std::islower(static_cast<unsigned char>(line[0]))) {
      return bad("line '" + line.substr(0, 40) + "' is not '<letter>=<value>'");
    }
    if (first && line != "v=0") return bad("must start with 'v=0'");
    first = false;
    if (line[0] == 'c') has_c = true;
    if (line.compare(0, 8, "m=video ") == 0) {
      const long port = std::strtol(line.c_str() + 8, nullptr, 10);
      if (port < 1 || port > 65535) return bad("m=video line without a port in 1..65535");
      has_video = true;
    }
  }
  if (!has_c) return bad("no connection line (c=IN IP4 <address>)");
  if (!has_video) return bad("no video media line (m=video <port> RTP/AVP <type>)");
  return Status::Ok();
}

// A free TCP port on `host`, from the kernel's ephemeral range. The port is
// released before FFmpeg binds it again; the kernel does not hand it out again
// right away, so the gap is harmless in practice.
StatusOr<int> PickFreeTcpPort(const std::string& host) {
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  if (inet_pton(AF_INET, host.c_str(), &sa.sin_addr) != 1) {
    return UnavailableError("rtsp_push_host '" + host + "' is not an IPv4 address");
  }
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return UnavailableError("no socket for an RTSP listener");
  socklen_t len = sizeof(sa);
  const bool ok = bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) == 0 &&
                  getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len) == 0;
  close(fd);
  if (!ok) return UnavailableError("no free port for an RTSP listener on " + host);
  return static_cast<int>(ntohs(sa.sin_port));
}

Status ValidateRequest(const v1::Session& r) {
  switch (r.source_case()) {
    case v1::Session::kUpload:
      break;
    case v1::Session::kRtspPull:
      SLAPSE_RETURN_IF_ERROR(ValidateRtspUrl(r.rtsp_pull().url()));
      SLAPSE_RETURN_IF_ERROR(ValidateReconnectPolicy(r.rtsp_pull().reconnect()));
      SLAPSE_RETURN_IF_ERROR(ValidateTimeouts(r.rtsp_pull().start_timeout_ms(),
                                              r.rtsp_pull().receive_timeout_ms(), "rtsp_pull"));
      break;
    case v1::Session::kRtspPush:
      SLAPSE_RETURN_IF_ERROR(ValidateRtspPath(r.rtsp_push().path()));
      SLAPSE_RETURN_IF_ERROR(ValidateTimeouts(r.rtsp_push().start_timeout_ms(),
                                              r.rtsp_push().receive_timeout_ms(), "rtsp_push"));
      break;
    case v1::Session::kRtpSdp:
      SLAPSE_RETURN_IF_ERROR(ValidateSdp(r.rtp_sdp().sdp()));
      SLAPSE_RETURN_IF_ERROR(ValidateTimeouts(r.rtp_sdp().start_timeout_ms(),
                                              r.rtp_sdp().receive_timeout_ms(), "rtp_sdp"));
      break;
    case v1::Session::SOURCE_NOT_SET:
      return InvalidArgumentError(
          "session.source is required (upload, rtsp_pull, rtsp_push, rtp_sdp)");
  }
  if (!r.has_intrinsics()) {
    return InvalidArgumentError("session.intrinsics is required (fx_px, fy_px, cx_px, cy_px)");
  }
  const v1::Intrinsics& k = r.intrinsics();
  if (!Finite(k.fx_px()) || !Finite(k.fy_px()) || k.fx_px() <= 0 || k.fy_px() <= 0) {
    return InvalidArgumentError("intrinsics: fx_px and fy_px must be finite and > 0, got " +
                                std::to_string(k.fx_px()) + ", " + std::to_string(k.fy_px()));
  }
  if (!Finite(k.cx_px()) || !Finite(k.cy_px())) {
    return InvalidArgumentError("intrinsics: cx_px and cy_px must be finite");
  }
  if (k.width_px() < 0 || k.height_px() < 0) {
    return InvalidArgumentError(
        "intrinsics: width_px and height_px must be >= 0 (0 = the stream's)");
  }
  const v1::PipelineOptions& p = r.pipeline_options();
  if (!Finite(p.eps_h_px()) || p.eps_h_px() < 0 || p.eps_h_px() > 100) {
    return InvalidArgumentError("pipeline_options.eps_h_px must be in [0, 100] px (0 = default)");
  }
  auto positive = [](double v) { return Finite(v) && v > 0; };
  switch (p.scale_source()) {
    case v1::PipelineOptions::FIRST_STEP:
      if (!positive(p.first_step_m())) {
        return InvalidArgumentError("pipeline_options.first_step_m must be > 0 for FIRST_STEP");
      }
      break;
    case v1::PipelineOptions::SPEED:
      if (!positive(p.speed_mps())) {
        return InvalidArgumentError("pipeline_options.speed_mps must be > 0 for SPEED");
      }
      break;
    case v1::PipelineOptions::CAMERA_HEIGHT:
      if (!positive(p.camera_height_m())) {
        return InvalidArgumentError(
            "pipeline_options.camera_height_m must be > 0 for CAMERA_HEIGHT");
      }
      break;
    default:
      break;
  }
  return Status::Ok();
}

PipelineOptions ToPipelineOptions(const v1::PipelineOptions& p) {
  PipelineOptions o;
  if (p.eps_h_px() > 0) o.extraction.eps_h_px = p.eps_h_px();
  switch (p.scale_source()) {
    case v1::PipelineOptions::FIRST_STEP:
      o.scale.source = ScaleOptions::Source::kFirstStep;
      o.scale.first_step_m = p.first_step_m();
      break;
    case v1::PipelineOptions::SPEED:
      o.scale.source = ScaleOptions::Source::kSpeed;
      o.scale.speed_mps = p.speed_mps();
      break;
    case v1::PipelineOptions::CAMERA_HEIGHT:
      o.scale.source = ScaleOptions::Source::kCameraHeight;
      o.scale.camera_height_m = p.camera_height_m();
      break;
    default:
      break;
  }
  return o;
}

void SetPose(const Rigid3d& t, v1::Pose* out) {
  out->set_tx(t.translation.x());
  out->set_ty(t.translation.y());
  out->set_tz(t.translation.z());
  out->set_qx(t.rotation.x());
  out->set_qy(t.rotation.y());
  out->set_qz(t.rotation.z());
  out->set_qw(t.rotation.w());
}

void SetVec(const Eigen::Vector3d& v, v1::Vec3* out) {
  out->set_x(v.x());
  out->set_y(v.y());
  out->set_z(v.z());
}

v1::PlaneMap::Plane ToPlane(const MapPlane& p) {
  v1::PlaneMap::Plane out;
  out.set_track_id(p.track_id);
  SetVec(p.normal_world, out.mutable_normal_world());
  out.set_distance(p.distance_m);
  out.set_first_seen_s(p.first_seen_s);
  out.set_last_seen_s(p.last_seen_s);
  out.set_observations(p.observations);
  return out;
}

}  // namespace

struct SessionManager::Session {
  Session(std::string n, size_t ring, UploadQueueOptions q)
      : name(std::move(n)),
        events(std::make_shared<EventLog>(ring)),
        upload(std::make_shared<UploadQueue>(q)) {}

  const std::string name;
  std::shared_ptr<EventLog> events;  // shared with watchers
  std::shared_ptr<UploadQueue> upload;
  std::atomic<bool> stop{false};
  std::condition_variable stop_cv;  // with `mu`: wakes a reconnect wait on stop

  mutable std::mutex mu;  // guards everything below
  v1::Session proto;      // state, stats, error, times (last_sequence filled on read)
  bool upload_started = false;
  Status ingest_error;  // why the upload broke off, if it did
  std::vector<v1::Trajectory::Point> trajectory;
  std::map<int, v1::PlaneMap::Plane> planes;
  bool metric = false;

  // Moves to `state` unless already terminal; appends the StateChange event
  // and, for a terminal state, closes the event log. Call with `mu` held.
  bool TransitionLocked(v1::Session::State state, const Status& why, const std::string& message) {
    if (IsTerminal(proto.state()) || proto.state() == state) return false;
    proto.set_state(state);
    *proto.mutable_update_time() = TimeUtil::GetCurrentTime();
    if (!why.ok()) {
      proto.mutable_error()->set_code(static_cast<int>(why.code()));
      proto.mutable_error()->set_message(why.message());
    }
    v1::SessionEvent e;
    e.mutable_state_change()->set_state(state);
    e.mutable_state_change()->set_message(why.ok() ? message : why.message());
    e.mutable_state_change()->set_error_code(static_cast<int>(why.code()));
    events->Append(std::move(e));
    if (IsTerminal(state)) {
      events->Close();
      upload->Close(
          why.ok() ? FailedPreconditionError("the session is " + v1::Session::State_Name(state))
                   : why);
    }
    return true;
  }
  // Waits up to `ms` or until the session is asked to stop; true if it was.
  bool WaitForStop(int ms) {
    std::unique_lock<std::mutex> lock(mu);
    return stop_cv.wait_for(lock, std::chrono::milliseconds(ms), [this] { return stop.load(); });
  }
  bool Transition(v1::Session::State state, const Status& why, const std::string& message = "") {
    std::lock_guard<std::mutex> lock(mu);
    return TransitionLocked(state, why, message);
  }
  v1::Session Snapshot() const {
    std::lock_guard<std::mutex> lock(mu);
    v1::Session out = proto;
    out.set_last_sequence(events->last_sequence());
    return out;
  }
};

SessionManager::SessionManager(SessionManagerOptions options) : options_(options) {
  const int n = options_.max_sessions < 1 ? 1 : options_.max_sessions;
  for (int i = 0; i < n; ++i) workers_.emplace_back([this] { WorkerLoop(); });
}

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
  SLAPSE_RETURN_IF_ERROR(ValidateRequest(request));
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
    s = std::make_shared<Session>("sessions/" + std::to_string(id), options_.event_ring_capacity,
                                  q);
    s->proto = request;
    s->proto.set_name(s->name);
    s->proto.clear_stats();
    s->proto.clear_error();
    s->proto.clear_ingest_url();
    if (request.has_rtsp_push()) {
      auto port = PickFreeTcpPort(options_.rtsp_push_host);
      if (!port.ok()) return port.status();
      s->proto.set_ingest_url("rtsp://" + options_.rtsp_push_host + ":" + std::to_string(*port) +
                              "/" + request.rtsp_push().path());
    }
    s->proto.set_state(v1::Session::STATE_UNSPECIFIED);
    *s->proto.mutable_create_time() = TimeUtil::GetCurrentTime();
    s->Transition(v1::Session::CREATED, Status::Ok(), "created; waiting for the stream");
    sessions_[id] = s;
    queue_.push_back(s);
  }
  work_ready_.notify_one();
  return s->Snapshot();
}

StatusOr<std::shared_ptr<SessionManager::Session>> SessionManager::Find(
    const std::string& name) const {
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
  if (request.page_size() < 0) return InvalidArgumentError("page_size must be >= 0");
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

void SessionManager::StopSession(Session* s, const std::string& why) {
  s->stop = true;
  // Transition takes `mu`, so a reconnect wait either saw `stop` or is
  // blocked in wait_for and gets the notification.
  s->Transition(v1::Session::STOPPED, Status::Ok(), why);
  s->stop_cv.notify_all();
}

StatusOr<v1::Session> SessionManager::Stop(const std::string& name) {
  auto s = Find(name);
  if (!s.ok()) return s.status();
  StopSession(s->get(), "stopped by StopSession");
  return (*s)->Snapshot();
}

Status SessionManager::Delete(const std::string& name) {
  auto s = Find(name);
  if (!s.ok()) return s.status();
  StopSession(s->get(), "deleted");
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
    s->TransitionLocked(v1::Session::RUNNING, Status::Ok(), "upload started");
  }
  Status st = s->upload->Write(std::move(first_bytes), cancelled);
  std::string chunk;
  while (st.ok() && next(&chunk)) st = s->upload->Write(std::move(chunk), cancelled);
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
    if (shutting_down_ && workers_.empty()) return;
    shutting_down_ = true;
    for (const auto& [id, s] : sessions_) all.push_back(s);
  }
  for (const auto& s : all) StopSession(s.get(), "the server is shutting down");
  work_ready_.notify_all();
  for (std::thread& t : workers_) {
    if (t.joinable()) t.join();
  }
  std::lock_guard<std::mutex> lock(mu_);
  workers_.clear();
}

void SessionManager::WorkerLoop() {
  for (;;) {
    std::shared_ptr<Session> s;
    {
      std::unique_lock<std::mutex> lock(mu_);
      work_ready_.wait(lock, [&] { return shutting_down_ || !queue_.empty(); });
      if (queue_.empty()) return;  // shutting down and nothing left
      s = std::move(queue_.front());
      queue_.pop_front();
    }
    RunSession(s);
  }
}

void SessionManager::RunSession(const std::shared_ptr<Session>& s) {
  // Ends the session: STOPPED if asked to stop, else FINISHED / FAILED.
  auto end = [&](Status status) {
    std::lock_guard<std::mutex> lock(s->mu);
    if (!s->ingest_error.ok()) status = s->ingest_error;
    if (s->stop) {
      s->TransitionLocked(v1::Session::STOPPED, Status::Ok(), "stopped");
    } else if (status.code() == StatusCode::kOutOfRange) {
      // FFmpeg's RTSP listener reports a TEARDOWN and a closed connection
      // alike (end of file), so both finish the session.
      s->TransitionLocked(v1::Session::FINISHED, Status::Ok(),
                          s->proto.has_rtsp_push()
                              ? "the publisher ended the stream (TEARDOWN or closed connection)"
                              : "the stream ended");
    } else {
      s->TransitionLocked(v1::Session::FAILED, status, "");
    }
  };
  if (s->stop) return end(CancelledError("stopped"));

  // Network sources are bounded by a deadline the interrupt callback checks:
  // start_timeout_ms from now (RTSP pull: from each connection attempt) until
  // the first frame, then receive_timeout_ms per Next() call (the time spent
  // blocked in I/O, not in the pipeline).
  v1::Session::SourceCase source;
  int start_ms = 0, receive_ms = 0;
  v1::ReconnectPolicy policy;  // RTSP pull
  std::string pull_url;        // RTSP pull, without credentials
  {
    std::lock_guard<std::mutex> lock(s->mu);
    source = s->proto.source_case();
    if (source == v1::Session::kRtspPull) {
      start_ms = s->proto.rtsp_pull().start_timeout_ms();
      receive_ms = s->proto.rtsp_pull().receive_timeout_ms();
      policy = s->proto.rtsp_pull().reconnect();
      pull_url = RedactUrl(s->proto.rtsp_pull().url());
    } else if (source == v1::Session::kRtspPush) {
      start_ms = s->proto.rtsp_push().start_timeout_ms();
      receive_ms = s->proto.rtsp_push().receive_timeout_ms();
    } else if (source == v1::Session::kRtpSdp) {
      start_ms = s->proto.rtp_sdp().start_timeout_ms();
      receive_ms = s->proto.rtp_sdp().receive_timeout_ms();
    }
  }
  if (start_ms == 0) start_ms = kDefaultStartTimeoutMs;
  if (receive_ms == 0) receive_ms = kDefaultReceiveTimeoutMs;
  const bool network = source != v1::Session::kUpload;
  auto now_ns = [] {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
        .count();
  };
  std::atomic<int64_t> deadline_ns{now_ns() + int64_t{start_ms} * 1000000};
  std::atomic<bool> timed_out{false};
  int64_t frames = 0;
  // Ends a network session whose deadline passed (the read was interrupted).
  auto end_timed_out = [&] {
    std::lock_guard<std::mutex> lock(s->mu);
    if (s->stop) {
      s->TransitionLocked(v1::Session::STOPPED, Status::Ok(), "stopped");
    } else if (frames == 0) {
      s->TransitionLocked(
          v1::Session::FAILED,
          Status(StatusCode::kDeadlineExceeded,
                 std::string(source == v1::Session::kRtspPush ? "no RTSP publisher sent video"
                                                              : "no RTP video arrived") +
                     " within start_timeout_ms=" + std::to_string(start_ms)),
          "");
    } else if (source == v1::Session::kRtpSdp) {
      s->TransitionLocked(v1::Session::FINISHED, Status::Ok(),
                          "no RTP video for receive_timeout_ms=" + std::to_string(receive_ms) +
                              ": the stream is taken as ended");
    } else {
      s->TransitionLocked(
          v1::Session::FAILED,
          UnavailableError("the RTSP publisher sent nothing for receive_timeout_ms=" +
                           std::to_string(receive_ms)),
          "");
    }
  };
  Session* raw = s.get();
  auto interrupt = [raw, network, &deadline_ns, &timed_out, now_ns] {
    if (raw->stop.load()) return true;
    if (network && now_ns() > deadline_ns.load()) {
      timed_out = true;
      return true;
    }
    return false;
  };

  // One pass per connection: upload, RTSP push and RTP/SDP have one; RTSP
  // pull reconnects on an outage while its policy allows (see RtspPull).
  std::optional<Pipeline> pipeline;
  StreamInfo first_info;
  Clock::time_point start;    // when the pipeline was made
  std::set<int> live_planes;  // track ids the filter held after the previous step
  std::map<int64_t, google::protobuf::Timestamp> received;  // frame index -> when read
  int64_t pairs = 0, tracked = 0;
  int64_t index_offset = 0;       // added to a connection's frame indices
  double time_offset_s = 0.0;     // and to its timestamps
  int64_t last_index = -1;        // of the last frame processed (offset)
  double last_timestamp_s = 0.0;  // of the last frame processed (offset)
  Clock::time_point last_frame_wall;
  int attempt = 0;     // retries in the current outage
  int reconnects = 0;  // retries over the session's life
  for (;;) {
    deadline_ns = now_ns() + int64_t{start_ms} * 1000000;
    timed_out = false;
    int64_t connection_frames = 0;
    Status status;  // how this connection ended
    auto reader = OpenReader(s, interrupt);
    if (!reader.ok()) {
      status = reader.status();
      if (source != v1::Session::kRtspPull) {
        if (timed_out) return end_timed_out();
        return end(status);
      }
    } else {
      const StreamInfo& info = (*reader)->info();
      if (!pipeline.has_value()) {
        Intrinsics k;
        v1::PipelineOptions popts;
        {
          std::lock_guard<std::mutex> lock(s->mu);
          const v1::Intrinsics& pk = s->proto.intrinsics();
          if ((pk.width_px() != 0 && pk.width_px() != info.width_px) ||
              (pk.height_px() != 0 && pk.height_px() != info.height_px)) {
            s->TransitionLocked(
                v1::Session::FAILED,
                InvalidArgumentError("intrinsics are for " + std::to_string(pk.width_px()) + "x" +
                                     std::to_string(pk.height_px()) + " but the stream is " +
                                     std::to_string(info.width_px) + "x" +
                                     std::to_string(info.height_px)),
                "");
            return;
          }
          k.fx_px = pk.fx_px();
          k.fy_px = pk.fy_px();
          k.cx_px = pk.cx_px();
          k.cy_px = pk.cy_px();
          k.width_px = info.width_px;
          k.height_px = info.height_px;
          popts = s->proto.pipeline_options();
        }
        pipeline.emplace(k, info.mv_sigma_px(), ToPipelineOptions(popts));
        first_info = info;
        start = Clock::now();
      } else if (info.width_px != first_info.width_px || info.height_px != first_info.height_px ||
                 info.codec_name != first_info.codec_name) {
        return end(FailedPreconditionError(
            "the stream changed across a reconnect from " + first_info.codec_name + " " +
            std::to_string(first_info.width_px) + "x" + std::to_string(first_info.height_px) +
            " to " + info.codec_name + " " + std::to_string(info.width_px) + "x" +
            std::to_string(info.height_px) + "; create a new session for the new stream"));
      } else {
        // A new connection: its frames do not connect to the ones before.
        pipeline->Break();
      }
      if (last_index >= 0) {
        // The new connection's frames follow the old ones, the outage's wall
        // time later (at least one frame interval).
        const double gap_s =
            std::max(std::chrono::duration<double>(Clock::now() - last_frame_wall).count(),
                     info.fps > 0 ? 1.0 / info.fps : 1e-3);
        index_offset = last_index + 1;
        time_offset_s = last_timestamp_s + gap_s;
      }

      FrameRecord frame;
      for (;;) {
        if (connection_frames > 0) deadline_ns = now_ns() + int64_t{receive_ms} * 1000000;
        status = (*reader)->Next(&frame);
        if (!status.ok()) break;
        ++connection_frames;
        if (++frames == 1 && network) {
          s->Transition(v1::Session::RUNNING, Status::Ok(), "receiving the stream");
        }
        attempt = 0;  // frames flow: an outage is over
        frame.index += index_offset;
        if (frame.prev_anchor_index >= 0) frame.prev_anchor_index += index_offset;
        if (frame.next_anchor_index >= 0) frame.next_anchor_index += index_offset;
        if (frame.coded_index >= 0) frame.coded_index += index_offset;
        frame.timestamp_s += time_offset_s;
        last_index = frame.index;
        last_timestamp_s = frame.timestamp_s;
        last_frame_wall = Clock::now();
        received[frame.index] = PreciseNow();
        auto step = pipeline->Push(frame);
        if (!step.ok()) return end(step.status());
        const double wall_s = std::chrono::duration<double>(Clock::now() - start).count();
        std::vector<v1::SessionEvent> events;
        {
          std::lock_guard<std::mutex> lock(s->mu);
          v1::SessionStats* st = s->proto.mutable_stats();
          st->set_frames(frames);
          // No figure from a blip: 0 until 10 frames or 0.25 s.
          st->set_fps(wall_s > 0 && (frames >= 10 || wall_s >= 0.25) ? frames / wall_s : 0.0);
          st->set_lag_ms(std::max(0.0, wall_s - frame.timestamp_s) * 1e3);
          st->set_stream_time_s(frame.timestamp_s);
          if (step->has_value()) {
            const PipelineStep& ps = **step;
            ++pairs;
            tracked += ps.tracking;
            st->set_anchor_pairs(pairs);
            st->set_tracked_pairs(tracked);
            st->set_planes(static_cast<int>(pipeline->plane_map().size()));
            *s->proto.mutable_update_time() = TimeUtil::GetCurrentTime();

            // Snapshots: a newly fixed scale rescales everything seen so far.
            const auto& traj = pipeline->trajectory();
            if (pipeline->metric() != s->metric) {
              s->metric = pipeline->metric();
              s->trajectory.clear();
              s->planes.clear();
              for (const auto& [id, mp] : pipeline->plane_map()) s->planes[id] = ToPlane(mp);
            }
            for (size_t i = s->trajectory.size(); i < traj.size(); ++i) {
              v1::Trajectory::Point p;
              p.set_anchor_index(traj[i].index);
              p.set_timestamp_s(traj[i].timestamp_s);
              SetPose(traj[i].world_from_cam, p.mutable_world_from_cam());
              s->trajectory.push_back(std::move(p));
            }

            v1::SessionEvent pose;
            v1::PoseUpdate* pu = pose.mutable_pose();
            pu->set_anchor_index(ps.later_index);
            pu->set_timestamp_s(ps.timestamp_s);
            SetPose(ps.world_from_cam, pu->mutable_world_from_cam());
            pu->set_tracking(ps.tracking);
            pu->set_metric(ps.metric);
            pu->set_note(ps.note);
            auto r = received.find(ps.later_index);
            if (r != received.end()) *pu->mutable_frame_received_time() = r->second;
            received.erase(received.begin(), received.upper_bound(ps.later_index));
            events.push_back(std::move(pose));

            std::set<int> now;
            for (const PlaneTrack& t : ps.planes) now.insert(t.track_id);
            auto plane_event = [&](int id, v1::PlaneEvent::Kind kind) {
              auto it = pipeline->plane_map().find(id);
              if (it == pipeline->plane_map().end()) return;
              s->planes[id] = ToPlane(it->second);
              v1::SessionEvent e;
              v1::PlaneEvent* pe = e.mutable_plane();
              pe->set_kind(kind);
              pe->set_track_id(id);
              SetVec(it->second.normal_world, pe->mutable_normal_world());
              pe->set_distance(it->second.distance_m);
              pe->set_anchor_index(ps.later_index);
              events.push_back(std::move(e));
            };
            for (int id : now) {
              plane_event(id,
                          live_planes.count(id) ? v1::PlaneEvent::UPDATED : v1::PlaneEvent::ADDED);
            }
            for (int id : live_planes) {
              if (!now.count(id)) plane_event(id, v1::PlaneEvent::REMOVED);
            }
            live_planes = std::move(now);
          }
        }
        for (auto& e : events) {
          if (e.has_pose()) *e.mutable_pose()->mutable_emit_time() = PreciseNow();
          s->events->Append(std::move(e));
        }
      }
      if (source != v1::Session::kRtspPull) {
        if (timed_out && status.code() == StatusCode::kCancelled) return end_timed_out();
        return end(status);
      }
    }

    // RTSP pull: the connection ended or could not be made.
    if (s->stop) return end(CancelledError("stopped"));
    if (status.code() == StatusCode::kFailedPrecondition) return end(status);  // unusable stream
    std::string reason;
    if (timed_out && connection_frames == 0) {
      reason = "no video within start_timeout_ms=" + std::to_string(start_ms) + " of connecting";
    } else if (timed_out) {
      reason = "no video for receive_timeout_ms=" + std::to_string(receive_ms) + " after " +
               std::to_string(connection_frames) + " frames";
    } else if (status.code() == StatusCode::kOutOfRange) {
      reason = "the stream ended (end of file: RTCP BYE or a closed connection) after " +
               std::to_string(connection_frames) + " frames";
    } else {
      reason = status.message();
    }
    if (attempt >= policy.max_attempts()) {
      std::lock_guard<std::mutex> lock(s->mu);
      if (s->stop) {
        s->TransitionLocked(v1::Session::STOPPED, Status::Ok(), "stopped");
      } else if (policy.max_attempts() == 0 && connection_frames > 0 && !timed_out &&
                 status.code() == StatusCode::kOutOfRange) {
        s->TransitionLocked(v1::Session::FINISHED, Status::Ok(),
                            reason + "; no reconnect (reconnect.max_attempts is 0)");
      } else if (policy.max_attempts() == 0) {
        s->TransitionLocked(v1::Session::FAILED,
                            UnavailableError("rtsp_pull '" + pull_url + "': " + reason +
                                             " (no reconnect: reconnect.max_attempts is 0)"),
                            "");
      } else {
        s->TransitionLocked(v1::Session::FAILED,
                            UnavailableError("rtsp_pull '" + pull_url + "': gave up after " +
                                             std::to_string(attempt) +
                                             " reconnect attempt(s); last error: " + reason),
                            "");
      }
      return;
    }
    ++attempt;
    ++reconnects;
    const int delay_ms = ReconnectDelayMs(policy, attempt);
    {
      std::lock_guard<std::mutex> lock(s->mu);
      s->proto.mutable_stats()->set_reconnects(reconnects);
      *s->proto.mutable_update_time() = TimeUtil::GetCurrentTime();
    }
    v1::SessionEvent e;
    v1::Reconnecting* r = e.mutable_reconnecting();
    r->set_attempt(attempt);
    r->set_max_attempts(policy.max_attempts());
    r->set_delay_ms(delay_ms);
    r->set_reason(reason);
    s->events->Append(std::move(e));
    if (reader.ok()) reader->reset();  // close the old connection before waiting
    if (s->WaitForStop(delay_ms)) return end(CancelledError("stopped"));
  }
}

StatusOr<std::unique_ptr<MvReader>> SessionManager::OpenReader(const std::shared_ptr<Session>& s,
                                                               std::function<bool()> interrupt) {
  MvReaderOptions o;
  o.interrupt = std::move(interrupt);
  const v1::Session req = s->Snapshot();
  switch (req.source_case()) {
    case v1::Session::kRtspPull: {
      // FFmpeg's RTSP client: DESCRIBE / SETUP / PLAY with RTP interleaved on
      // the TCP connection. "timeout" is its socket I/O timeout (connect and
      // reads) in microseconds; the interrupt callback bounds the rest.
      const std::string& url = req.rtsp_pull().url();
      const int receive_ms = req.rtsp_pull().receive_timeout_ms() > 0
                                 ? req.rtsp_pull().receive_timeout_ms()
                                 : kDefaultReceiveTimeoutMs;
      o.format = "rtsp";
      o.format_options = {{"rtsp_transport", "tcp"},
                          {"allowed_media_types", "video"},
                          {"timeout", std::to_string(int64_t{receive_ms} * 1000)}};
      auto reader = MvReader::Open(url, o);
      if (reader.ok()) return reader;
      // FFmpeg's messages quote the URL: drop its credentials.
      std::string message = reader.status().message();
      const std::string shown = RedactUrl(url);
      for (size_t at = message.find(url); at != std::string::npos;
           at = message.find(url, at + shown.size())) {
        message.replace(at, url.size(), shown);
      }
      return Status(reader.status().code(), message);
    }
    case v1::Session::kRtspPush: {
      // FFmpeg's RTSP demuxer in listen mode: accepts one publisher, answers
      // its ANNOUNCE / SETUP / RECORD, then reads its RTP (TCP interleaved
      // or UDP). "timeout" is FFmpeg's socket I/O timeout in microseconds.
      const int receive_ms = req.rtsp_push().receive_timeout_ms() > 0
                                 ? req.rtsp_push().receive_timeout_ms()
                                 : kDefaultReceiveTimeoutMs;
      o.format = "rtsp";
      o.format_options = {{"rtsp_flags", "listen"},
                          {"timeout", std::to_string(int64_t{receive_ms} * 1000)}};
      return MvReader::Open(req.ingest_url(), o);
    }
    case v1::Session::kRtpSdp: {
      // The SDP goes to a private temp file (mkstemp: mode 0600) that is
      // removed once FFmpeg has parsed it; only file, udp and rtp are allowed.
      const char* tmp = std::getenv("TMPDIR");
      std::string path =
          std::string(tmp != nullptr && *tmp != '\0' ? tmp : "/tmp") + "/slapse-sdp-XXXXXX";
      const int fd = mkstemp(path.data());
      if (fd < 0) return UnavailableError("cannot create a temp file for the SDP");
      const std::string& sdp = req.rtp_sdp().sdp();
      size_t done = 0;
      while (done < sdp.size()) {
        const ssize_t n = write(fd, sdp.data() + done, sdp.size() - done);
        if (n <= 0) break;
        done += static_cast<size_t>(n);
      }
      close(fd);
      if (done != sdp.size()) {
        unlink(path.c_str());
        return UnavailableError("cannot write the SDP to a temp file");
      }
      o.format = "sdp";
      o.format_options = {{"protocol_whitelist", "file,udp,rtp"}, {"allowed_media_types", "video"}};
      auto reader = MvReader::Open(path, o);
      unlink(path.c_str());
      return reader;
    }
    default:
      return MvReader::Open(std::make_unique<UploadByteSource>(s->upload), o);
  }
}

}  // namespace slapse::server
