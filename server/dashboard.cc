#include "server/dashboard.h"

#include <google/protobuf/util/json_util.h>

#include <chrono>
#include <memory>
#include <sstream>
#include <vector>

#include "api/convert.h"
#include "api/validate.h"
#include "core/pipeline/result_io.h"

namespace slapse::server {
namespace {

constexpr char kJson[] = "application/json; charset=utf-8";
constexpr char kTokenCookie[] = "slapse_token";
// Points / planes per store page when a download gathers a whole trajectory.
constexpr int kDownloadPage = 10000;
// Events per SSE read, and how long one read waits before a keep-alive.
constexpr size_t kEventBatch = 256;
constexpr auto kEventPoll = std::chrono::milliseconds(500);
// Overlay pictures: default and largest width, px.
constexpr int kOverlayWidth = 640;
constexpr int kOverlayMaxWidth = 4096;

std::string ToJson(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;
  o.always_print_primitive_fields = true;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(message, &out, o);
  return out;
}

int HttpStatusOf(StatusCode code) {
  switch (code) {
    case StatusCode::kOk:
      return 200;
    case StatusCode::kInvalidArgument:
    case StatusCode::kOutOfRange:
      return 400;
    case StatusCode::kNotFound:
      return 404;
    case StatusCode::kAlreadyExists:
    case StatusCode::kAborted:
    case StatusCode::kFailedPrecondition:
      return 409;
    case StatusCode::kPermissionDenied:
      return 403;
    case StatusCode::kResourceExhausted:
      return 429;
    case StatusCode::kUnavailable:
      return 503;
    case StatusCode::kDeadlineExceeded:
      return 504;
    case StatusCode::kUnimplemented:
      return 501;
    default:
      return code == kUnauthenticated ? 401 : 500;
  }
}

// An error as it may leave the server: an ErrorStatus, its message masked.
HttpResponse ErrorResponse(const Status& s) {
  v1::ErrorStatus e;
  e.set_code(static_cast<int>(s.code()));
  e.set_message(api::RedactText(s.message()));
  HttpResponse r{HttpStatusOf(s.code()), kJson, ToJson(e)};
  if (s.code() == kUnauthenticated) r.headers.emplace_back("WWW-Authenticate", "Bearer");
  return r;
}

HttpResponse JsonResponse(const google::protobuf::Message& m) {
  HttpResponse r{200, kJson, ToJson(m)};
  r.headers.emplace_back("Cache-Control", "no-store");
  return r;
}

template <typename T>
HttpResponse Reply(const StatusOr<T>& result) {
  return result.ok() ? JsonResponse(*result) : ErrorResponse(result.status());
}

// The value of cookie `name` in a Cookie header ("a=b; c=d"), or "".
std::string CookieValue(const std::string& header, const std::string& name) {
  std::istringstream in(header);
  std::string part;
  while (std::getline(in, part, ';')) {
    const size_t start = part.find_first_not_of(' ');
    if (start == std::string::npos) continue;
    part = part.substr(start);
    if (part.compare(0, name.size() + 1, name + "=") == 0) return part.substr(name.size() + 1);
  }
  return "";
}

// The request's token: "Authorization: Bearer <token>", else the login cookie.
std::string TokenOf(const HttpRequest& r) {
  const std::string auth = r.Header("Authorization");
  if (auth.rfind("Bearer ", 0) == 0) return auth.substr(7);
  return CookieValue(r.Header("Cookie"), kTokenCookie);
}

// An integer `v` (empty: `fallback`); INVALID_ARGUMENT naming it `what`.
StatusOr<int64_t> ParseInt(const std::string& v, const std::string& what, int64_t fallback) {
  if (v.empty()) return fallback;
  size_t used = 0;
  try {
    const int64_t x = std::stoll(v, &used);
    if (used == v.size()) return x;
  } catch (const std::exception&) {
  }
  return InvalidArgumentError(what + " must be an integer");
}

// An integer query parameter (absent: `fallback`).
StatusOr<int64_t> IntParam(const HttpRequest& r, const std::string& name, int64_t fallback) {
  return ParseInt(r.Param(name), "query parameter '" + name + "'", fallback);
}

StatusOr<double> DoubleParam(const HttpRequest& r, const std::string& name) {
  const std::string v = r.Param(name);
  if (v.empty()) return 0.0;
  size_t used = 0;
  try {
    const double x = std::stod(v, &used);
    if (used == v.size()) return x;
  } catch (const std::exception&) {
  }
  return InvalidArgumentError("query parameter '" + name + "' must be a number");
}

class Dashboard {
 public:
  Dashboard(SessionManager* sessions, Authenticator* auth, bool https)
      : sessions_(sessions), auth_(auth), https_(https) {}

  SessionManager* sessions() const { return sessions_; }
  bool AuthOn() const { return auth_ != nullptr && auth_->enabled(); }
  // The caller from the request's token; PERMISSION_DENIED for a read-only
  // one when `op` changes state (op non-empty).
  StatusOr<Caller> Authorize(const HttpRequest& r, const std::string& op = "") const;
  // The caller, and `name` is one of its sessions (else NOT_FOUND).
  StatusOr<Caller> AuthorizeSession(const HttpRequest& r, const std::string& op = "") const;

  HttpResponse Page(const HttpRequest& r, const std::string& asset) const;
  HttpResponse Login(const HttpRequest& r) const;
  HttpResponse List(const HttpRequest& r) const;
  HttpResponse Trajectory(const HttpRequest& r) const;
  HttpResponse Planes(const HttpRequest& r) const;
  HttpResponse Download(const HttpRequest& r) const;
  HttpResponse Events(const HttpRequest& r) const;
  HttpResponse Overlay(const HttpRequest& r) const;

 private:
  SessionManager* const sessions_;
  Authenticator* const auth_;
  const bool https_;  // the login cookie is then Secure
};

const WebAsset* FindAsset(const std::string& path) {
  for (size_t i = 0; i < kWebAssetCount; ++i) {
    if (path == kWebAssets[i].path) return &kWebAssets[i];
  }
  return nullptr;
}

HttpResponse AssetResponse(const WebAsset& a, int status = 200) {
  HttpResponse r{status, a.content_type,
                 std::string(reinterpret_cast<const char*>(a.data), a.size)};
  r.headers.emplace_back("Cache-Control", "no-cache");
  r.headers.emplace_back("X-Content-Type-Options", "nosniff");
  r.headers.emplace_back("Content-Security-Policy",
                         "default-src 'self'; img-src 'self' data: blob:; frame-ancestors 'none'");
  return r;
}

StatusOr<Caller> Dashboard::Authorize(const HttpRequest& r, const std::string& op) const {
  if (auth_ == nullptr) return Caller{};
  const std::string token = TokenOf(r);
  if (AuthOn() && token.empty()) {
    return Status(kUnauthenticated,
                  "this server requires a token: sign in at / or send 'Authorization: Bearer "
                  "<token>'");
  }
  auto caller = auth_->AuthenticateToken(token);
  if (!caller.ok()) return caller.status();
  if (!op.empty()) SLAPSE_RETURN_IF_ERROR(Authenticator::CheckMayWrite(*caller, op));
  return caller;
}

StatusOr<Caller> Dashboard::AuthorizeSession(const HttpRequest& r, const std::string& op) const {
  auto caller = Authorize(r, op);
  if (!caller.ok()) return caller.status();
  const std::string name = r.Param("name");
  if (name.empty())
    return InvalidArgumentError("query parameter 'name' (sessions/{id}) is required");
  if (AuthOn()) {
    auto s = sessions_->Get(name);
    if (!s.ok()) return s.status();
    if (s->tenant() != caller->tenant) return SessionNotFoundError(name);
  }
  return caller;
}

HttpResponse Dashboard::Page(const HttpRequest& r, const std::string& asset) const {
  if (AuthOn() && !Authorize(r).ok()) {
    return AssetResponse(*FindAsset("login.html"), TokenOf(r).empty() ? 200 : 401);
  }
  return AssetResponse(*FindAsset(asset));
}

HttpResponse Dashboard::Login(const HttpRequest& r) const {
  const std::string token = r.Param("token");
  if (auth_ != nullptr && !auth_->AuthenticateToken(token).ok()) {
    HttpResponse bad{303, "text/plain; charset=utf-8", "unknown token\n"};
    bad.headers.emplace_back("Location", "/?login=failed");
    return bad;
  }
  HttpResponse ok{303, "text/plain; charset=utf-8", "signed in\n"};
  ok.headers.emplace_back("Location", "/");
  ok.headers.emplace_back("Set-Cookie", std::string(kTokenCookie) + "=" + token +
                                            "; Path=/; HttpOnly; SameSite=Strict" +
                                            (https_ ? "; Secure" : ""));
  return ok;
}

HttpResponse Dashboard::List(const HttpRequest& r) const {
  auto caller = Authorize(r);
  if (!caller.ok()) return ErrorResponse(caller.status());
  v1::ListSessionsRequest q;
  q.set_filter(r.Param("filter"));
  q.set_order_by(r.Param("order_by"));
  q.set_page_token(r.Param("page_token"));
  auto page_size = IntParam(r, "page_size", 0);
  if (!page_size.ok()) return ErrorResponse(page_size.status());
  q.set_page_size(static_cast<int32_t>(*page_size));
  if (const std::string state = r.Param("state"); !state.empty()) {
    v1::Session::State s;
    if (!v1::Session::State_Parse(state, &s)) {
      return ErrorResponse(
          InvalidArgumentError("query parameter 'state' must be a Session.State "
                               "name (CREATED, RUNNING, ...), not '" +
                               state + "'"));
    }
    q.set_state_filter(s);
  }
  auto list = sessions_->List(q, AuthOn() ? &caller->tenant : nullptr);
  if (!list.ok()) return ErrorResponse(list.status());
  for (v1::Session& s : *list->mutable_sessions()) api::RedactSession(&s);
  return JsonResponse(*list);
}

HttpResponse Dashboard::Trajectory(const HttpRequest& r) const {
  if (auto c = AuthorizeSession(r); !c.ok()) return ErrorResponse(c.status());
  v1::GetTrajectoryRequest q;
  q.set_name(r.Param("name"));
  q.set_page_token(r.Param("page_token"));
  auto page_size = IntParam(r, "page_size", kDownloadPage);
  auto start = DoubleParam(r, "start_time_s");
  auto end = DoubleParam(r, "end_time_s");
  if (!page_size.ok()) return ErrorResponse(page_size.status());
  if (!start.ok()) return ErrorResponse(start.status());
  if (!end.ok()) return ErrorResponse(end.status());
  q.set_page_size(static_cast<int32_t>(*page_size));
  q.set_start_time_s(*start);
  q.set_end_time_s(*end);
  return Reply(sessions_->GetTrajectory(q));
}

HttpResponse Dashboard::Planes(const HttpRequest& r) const {
  if (auto c = AuthorizeSession(r); !c.ok()) return ErrorResponse(c.status());
  v1::GetPlaneMapRequest q;
  q.set_name(r.Param("name"));
  q.set_page_token(r.Param("page_token"));
  auto page_size = IntParam(r, "page_size", kDownloadPage);
  if (!page_size.ok()) return ErrorResponse(page_size.status());
  q.set_page_size(static_cast<int32_t>(*page_size));
  return Reply(sessions_->GetPlaneMap(q));
}

// Every page of the session's trajectory and plane map.
Status GatherResults(const SessionManager& sessions, const std::string& name,
                     v1::Trajectory* trajectory, v1::PlaneMap* planes) {
  v1::GetTrajectoryRequest tq;
  tq.set_name(name);
  tq.set_page_size(kDownloadPage);
  do {
    auto page = sessions.GetTrajectory(tq);
    if (!page.ok()) return page.status();
    trajectory->set_name(page->name());
    trajectory->set_metric(page->metric());
    for (auto& p : *page->mutable_points()) *trajectory->add_points() = std::move(p);
    tq.set_page_token(page->next_page_token());
  } while (!tq.page_token().empty());
  if (planes == nullptr) return Status::Ok();
  v1::GetPlaneMapRequest pq;
  pq.set_name(name);
  pq.set_page_size(kDownloadPage);
  do {
    auto page = sessions.GetPlaneMap(pq);
    if (!page.ok()) return page.status();
    for (auto& p : *page->mutable_planes()) *planes->add_planes() = std::move(p);
    pq.set_page_token(page->next_page_token());
  } while (!pq.page_token().empty());
  return Status::Ok();
}

HttpResponse Dashboard::Download(const HttpRequest& r) const {
  if (auto c = AuthorizeSession(r); !c.ok()) return ErrorResponse(c.status());
  const std::string format = r.Param("format");
  if (format != "tum" && format != "kitti" && format != "json") {
    return ErrorResponse(
        InvalidArgumentError("query parameter 'format' must be tum, kitti or json"));
  }
  const std::string name = r.Param("name");
  v1::Trajectory trajectory;
  v1::PlaneMap planes;
  if (Status s = GatherResults(*sessions_, name, &trajectory, format == "json" ? &planes : nullptr);
      !s.ok()) {
    return ErrorResponse(s);
  }
  const auto traj = api::TrajectoryFromProto(trajectory);
  std::ostringstream out;
  std::string file = name.substr(name.find('/') + 1);
  if (format == "tum") {
    WriteTrajectoryTum(traj, out);
    file += "_trajectory_tum.txt";
  } else if (format == "kitti") {
    WriteTrajectoryKitti(traj, out);
    file += "_trajectory_kitti.txt";
  } else {
    ResultJsonOptions o;
    o.seen_at_frames = false;  // a server's plane map does not keep them
    o.trajectory = &traj;
    WriteResultJson(api::PlaneMapFromProto(planes), trajectory.metric(), o, out);
    file += "_result.json";
  }
  HttpResponse res{200, format == "json" ? kJson : "text/plain; charset=utf-8", out.str()};
  res.headers.emplace_back("Content-Disposition", "attachment; filename=\"" + file + "\"");
  return res;
}

// One server-sent event: `id:` the sequence, data the event's JSON (one line).
std::string SseEvent(const v1::SessionEvent& e) {
  return "id: " + std::to_string(e.sequence()) + "\ndata: " + ToJson(e) + "\n\n";
}

HttpResponse Dashboard::Events(const HttpRequest& r) const {
  if (auto c = AuthorizeSession(r); !c.ok()) return ErrorResponse(c.status());
  auto log = sessions_->Events(r.Param("name"));
  if (!log.ok()) return ErrorResponse(log.status());
  // The browser's Last-Event-ID (a reconnect) wins over `after` (the snapshot's).
  const std::string last_id = r.Header("Last-Event-ID");
  auto cursor = ParseInt(last_id.empty() ? r.Param("after") : last_id, "the event cursor", 0);
  if (!cursor.ok() || *cursor < 0) {
    return ErrorResponse(InvalidArgumentError(
        "the event cursor (Last-Event-ID or 'after') must be a sequence number >= 0"));
  }
  HttpResponse res{200, "text/event-stream", ""};
  res.headers.emplace_back("Cache-Control", "no-store");
  struct State {
    std::shared_ptr<EventLog> log;
    uint64_t cursor;
    bool started = false;
  };
  auto state = std::make_shared<State>(State{*log, static_cast<uint64_t>(*cursor)});
  res.stream = [state](const HttpWrite& write) {
    if (!state->started) {
      state->started = true;
      return write("retry: 1000\n\n");
    }
    std::vector<v1::SessionEvent> events;
    bool ended = false;
    Status s = state->log->Read(state->cursor, kEventBatch,
                                std::chrono::steady_clock::now() + kEventPoll, &events, &ended);
    if (!s.ok()) {
      v1::ErrorStatus e;
      e.set_code(static_cast<int>(s.code()));
      e.set_message(api::RedactText(s.message()));
      write("event: failure\ndata: " + ToJson(e) + "\n\n");
      return false;
    }
    for (v1::SessionEvent& e : events) {
      api::RedactEvent(&e);
      if (!write(SseEvent(e))) return false;
      state->cursor = e.sequence();
    }
    if (ended) {
      write("event: end\ndata: {}\n\n");
      return false;
    }
    // A comment when there was nothing: finds a client that went away.
    return events.empty() ? write(": keep-alive\n\n") : true;
  };
  return res;
}

HttpResponse Dashboard::Overlay(const HttpRequest& r) const {
  if (auto c = AuthorizeSession(r); !c.ok()) return ErrorResponse(c.status());
  auto kind = ParseOverlayKind(r.Param("kind"));
  if (!kind.ok()) return ErrorResponse(kind.status());
  auto width = IntParam(r, "max_width_px", kOverlayWidth);
  if (!width.ok()) return ErrorResponse(width.status());
  if (*width < 16 || *width > kOverlayMaxWidth) {
    return ErrorResponse(InvalidArgumentError("query parameter 'max_width_px' must be in [16, " +
                                              std::to_string(kOverlayMaxWidth) + "]"));
  }
  auto overlays = sessions_->Overlays(r.Param("name"));
  if (!overlays.ok()) return ErrorResponse(overlays.status());
  auto png = (*overlays)->Png(*kind, static_cast<int>(*width));
  if (!png.ok()) return ErrorResponse(png.status());
  HttpResponse res{200, "image/png", std::move(png->png)};
  res.headers.emplace_back("Cache-Control", "no-store");
  res.headers.emplace_back("X-Slapse-Frame", std::to_string(png->frame_index));
  res.headers.emplace_back("X-Slapse-Count", std::to_string(png->count));
  return res;
}

// The routes; their handlers share `d`.
void Mount(const std::shared_ptr<const Dashboard>& d, HttpServer* http) {
  http->Get("/", [d](const HttpRequest& r) { return d->Page(r, "index.html"); });
  http->Get("/index.html", [d](const HttpRequest& r) { return d->Page(r, "index.html"); });
  http->Get("/session.html", [d](const HttpRequest& r) { return d->Page(r, "session.html"); });
  for (size_t i = 0; i < kWebAssetCount; ++i) {
    const WebAsset& a = kWebAssets[i];
    const std::string path = a.path;
    if (path.size() > 5 && path.substr(path.size() - 5) == ".html") continue;  // pages above
    http->Get("/" + path, [&a](const HttpRequest&) { return AssetResponse(a); });
  }
  http->Post("/login", [d](const HttpRequest& r) { return d->Login(r); });
  http->Post("/logout", [](const HttpRequest&) {
    HttpResponse r{303, "text/plain; charset=utf-8", "signed out\n"};
    r.headers.emplace_back("Location", "/");
    r.headers.emplace_back("Set-Cookie", std::string(kTokenCookie) +
                                             "=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0");
    return r;
  });
  http->Get("/api/sessions", [d](const HttpRequest& r) { return d->List(r); });
  http->Get("/api/session", [d](const HttpRequest& r) {
    if (auto c = d->AuthorizeSession(r); !c.ok()) return ErrorResponse(c.status());
    auto s = d->sessions()->Get(r.Param("name"));
    if (s.ok()) api::RedactSession(&*s);
    return Reply(s);
  });
  http->Get("/api/trajectory", [d](const HttpRequest& r) { return d->Trajectory(r); });
  http->Get("/api/planes", [d](const HttpRequest& r) { return d->Planes(r); });
  http->Get("/api/download", [d](const HttpRequest& r) { return d->Download(r); });
  http->Get("/api/events", [d](const HttpRequest& r) { return d->Events(r); });
  http->Get("/api/overlay", [d](const HttpRequest& r) { return d->Overlay(r); });
  http->Post("/api/stop", [d](const HttpRequest& r) {
    if (auto c = d->AuthorizeSession(r, "StopSession"); !c.ok()) return ErrorResponse(c.status());
    auto s = d->sessions()->Stop(r.Param("name"));
    if (s.ok()) api::RedactSession(&*s);
    return Reply(s);
  });
  http->Post("/api/delete", [d](const HttpRequest& r) {
    if (auto c = d->AuthorizeSession(r, "DeleteSession"); !c.ok()) return ErrorResponse(c.status());
    const Status s = d->sessions()->Delete(r.Param("name"));
    return s.ok() ? JsonResponse(v1::DeleteSessionResponse()) : ErrorResponse(s);
  });
}

}  // namespace

void MountDashboard(HttpServer* http, SessionManager* sessions, Authenticator* auth) {
  Mount(std::make_shared<const Dashboard>(sessions, auth, http->tls()), http);
}

}  // namespace slapse::server
