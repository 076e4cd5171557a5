// The slapse service from the command line: `serve` runs the gRPC server;
// create, upload, watch, list, get, stop and delete talk to one (--server).
#include <signal.h>

#include <google/protobuf/util/json_util.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>

#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "client/lib/client.h"
#include "api/convert.h"
#include "core/common/intrinsics_io.h"
#include "server/server.h"

namespace slapse::cli {
namespace {

const FlagSpec kServerFlag{"server", "HOST:PORT", "the slapse server", "localhost:50051"};

// Parses flags; returns -1 to go on, else the exit code (help printed or usage error).
int ParseOrExit(Flags& flags, const char* command, int argc, char** argv, size_t positional) {
  if (Status s = flags.Parse(argc, argv); !s.ok()) return Fail(command, s.message(), 2);
  if (flags.help_requested()) {
    std::printf("%s", flags.Usage().c_str());
    return 0;
  }
  if (flags.positional().size() != positional) {
    return Fail(command, "expected " + std::to_string(positional) + " argument(s) (see --help)", 2);
  }
  return -1;
}

std::unique_ptr<client::SlapseClient> Connect(const Flags& flags, double watch_timeout_s = 0) {
  client::ClientOptions o;
  o.watch_timeout_s = watch_timeout_s;
  return client::SlapseClient::Connect(flags.GetString("server"), o);
}

std::string Json(const google::protobuf::Message& m) {
  std::string out;
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;
  (void)google::protobuf::util::MessageToJsonString(m, &out, o);
  return out;
}

const char* StateName(v1::Session::State s) {
  switch (s) {
    case v1::Session::CREATED:
      return "CREATED";
    case v1::Session::RUNNING:
      return "RUNNING";
    case v1::Session::FINISHED:
      return "FINISHED";
    case v1::Session::FAILED:
      return "FAILED";
    case v1::Session::STOPPED:
      return "STOPPED";
    default:
      return "?";
  }
}

void PrintSessionLine(const v1::Session& s) {
  std::printf("%-14s %-9s frames %-6lld pairs %-5lld tracked %-5lld planes %-4d %6.1f fps%s%s\n",
              s.name().c_str(), StateName(s.state()), static_cast<long long>(s.stats().frames()),
              static_cast<long long>(s.stats().anchor_pairs()),
              static_cast<long long>(s.stats().tracked_pairs()), s.stats().planes(),
              s.stats().fps(),
              s.error().message().empty() ? "" : "  error: ", s.error().message().c_str());
}

}  // namespace

int RunServe(int argc, char** argv) {
  Flags flags(
      "serve", "[options]   (runs until SIGINT or SIGTERM, then shuts down gracefully)",
      {{"address", "ADDR", "address to listen on", "0.0.0.0"},
       {"port", "PORT", "TCP port (0: pick a free one)", "50051"},
       {"max-sessions", "N", "sessions active at once (worker threads)", "4"},
       {"max-upload-mb", "MB", "bytes one upload may send, MiB (0: no limit)", "4096"},
       {"event-ring", "N", "events kept per session for resuming watchers", "4096"},
       {"rtsp-host", "IPV4", "address RTSP push listeners bind and advertise", "127.0.0.1"}});
  if (int rc = ParseOrExit(flags, "serve", argc, argv, 0); rc >= 0) return rc;
  server::ServerOptions o;
  o.address = flags.GetString("address");
  auto port = flags.GetInt("port", 0, 65535);
  auto max_sessions = flags.GetInt("max-sessions", 1, 1024);
  auto max_upload = flags.GetInt("max-upload-mb", 0, int64_t{1} << 30);
  auto ring = flags.GetInt("event-ring", 1, int64_t{1} << 24);
  for (const Status* s :
       {&port.status(), &max_sessions.status(), &max_upload.status(), &ring.status()}) {
    if (!s->ok()) return Fail("serve", s->message(), 2);
  }
  o.port = static_cast<int>(*port);
  o.sessions.max_sessions = static_cast<int>(*max_sessions);
  o.sessions.max_upload_bytes = *max_upload << 20;
  o.sessions.event_ring_capacity = static_cast<size_t>(*ring);
  o.sessions.rtsp_push_host = flags.GetString("rtsp-host");

  // Block the shutdown signals before gRPC starts its threads; wait for them below.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto server = server::SlapseServer::Start(o);
  if (!server.ok()) return Fail("serve", server.status().message());
  std::printf("slapse serving on %s:%d (max %d sessions; health + reflection on)\n",
              o.address.c_str(), (*server)->port(), o.sessions.max_sessions);
  std::fflush(stdout);
  int sig = 0;
  sigwait(&signals, &sig);
  std::fprintf(stderr, "slapse serve: %s, shutting down\n", sig == SIGINT ? "SIGINT" : "SIGTERM");
  (*server)->Shutdown();
  return 0;
}

int RunCreate(int argc, char** argv) {
  Flags flags(
      "create",
      "--upload|--rtsp-pull URL|--rtsp-push PATH|--rtp-sdp FILE --intrinsics SPEC [options]\n"
      "  (prints the session name; for --rtsp-push also the URL to publish to)",
      {kServerFlag,
       {"upload", "", "the stream comes through 'slapse upload'", ""},
       {"rtsp-pull", "URL", "the server pulls rtsp[s]://[user:pass@]host[:port]/path (over TCP)",
        ""},
       {"rtsp-push", "PATH", "a camera publishes (RTSP ANNOUNCE/RECORD) to the printed URL", ""},
       {"rtp-sdp", "FILE", "the server receives the RTP that this SDP file describes", ""},
       {"start-timeout-ms", "MS", "network sources: wait for the first frame (0: 60000)", "0"},
       {"receive-timeout-ms", "MS", "network sources: wait between frames (0: 5000)", "0"},
       {"reconnect-attempts", "N",
        "--rtsp-pull: retries per outage (drop, end, unreachable; 0: none)", "0"},
       {"reconnect-interval-ms", "MS", "--rtsp-pull: wait before the first retry (0: 1000)", "0"},
       {"reconnect-backoff", "X", "--rtsp-pull: each further wait is X times longer (0: 2)", "0"},
       {"reconnect-max-interval-ms", "MS", "--rtsp-pull: longest wait (0: 30000)", "0"},
       {"intrinsics", "SPEC", "FILE.json or 'fx,fy,cx,cy' (pixels)", ""},
       {"eps-h", "PX", "homography inlier threshold (0: default)", "0"},
       {"first-step-m", "M", "metric scale: length of the first tracked step", ""},
       {"speed-kmh", "V", "metric scale: speed at the start", ""},
       {"camera-height-m", "H", "metric scale: camera height above the road", ""}});
  if (int rc = ParseOrExit(flags, "create", argc, argv, 0); rc >= 0) return rc;
  const int sources = flags.GetBool("upload") + flags.Has("rtsp-pull") + flags.Has("rtsp-push") +
                      flags.Has("rtp-sdp");
  if (sources != 1) {
    return Fail("create",
                "give one source: --upload, --rtsp-pull URL, --rtsp-push PATH or --rtp-sdp FILE",
                2);
  }
  auto start_ms = flags.GetInt("start-timeout-ms", 0, 3600000);
  auto receive_ms = flags.GetInt("receive-timeout-ms", 0, 3600000);
  if (!start_ms.ok()) return Fail("create", start_ms.status().message(), 2);
  if (!receive_ms.ok()) return Fail("create", receive_ms.status().message(), 2);
  const std::string spec = flags.GetString("intrinsics");
  if (spec.empty()) return Fail("create", "--intrinsics is required", 2);
  if (spec.rfind("hfov=", 0) == 0) {
    return Fail("create", "hfov= needs the stream size; give FILE.json or 'fx,fy,cx,cy'", 2);
  }
  StatusOr<Intrinsics> k = spec.size() > 5 && spec.substr(spec.size() - 5) == ".json"
                               ? ReadIntrinsicsJson(spec)
                               : ParseIntrinsicsSpec(spec, 0, 0);
  if (!k.ok()) return Fail("create", k.status().message(), 2);
  v1::Session request;
  if (flags.Has("rtsp-pull")) {
    // Ranges are the server's (it answers INVALID_ARGUMENT with the reason).
    auto attempts = flags.GetInt("reconnect-attempts", 0, INT32_MAX);
    auto interval = flags.GetInt("reconnect-interval-ms", 0, INT32_MAX);
    auto backoff = flags.GetDouble("reconnect-backoff", 0, 1e9);
    auto max_interval = flags.GetInt("reconnect-max-interval-ms", 0, INT32_MAX);
    for (const Status* s :
         {&attempts.status(), &interval.status(), &backoff.status(), &max_interval.status()}) {
      if (!s->ok()) return Fail("create", s->message(), 2);
    }
    v1::RtspPull* pull = request.mutable_rtsp_pull();
    pull->set_url(flags.GetString("rtsp-pull"));
    pull->set_start_timeout_ms(static_cast<int>(*start_ms));
    pull->set_receive_timeout_ms(static_cast<int>(*receive_ms));
    pull->mutable_reconnect()->set_max_attempts(static_cast<int>(*attempts));
    pull->mutable_reconnect()->set_initial_interval_ms(static_cast<int>(*interval));
    pull->mutable_reconnect()->set_backoff_multiplier(*backoff);
    pull->mutable_reconnect()->set_max_interval_ms(static_cast<int>(*max_interval));
  } else if (flags.Has("rtsp-push")) {
    request.mutable_rtsp_push()->set_path(flags.GetString("rtsp-push"));
    request.mutable_rtsp_push()->set_start_timeout_ms(static_cast<int>(*start_ms));
    request.mutable_rtsp_push()->set_receive_timeout_ms(static_cast<int>(*receive_ms));
  } else if (flags.Has("rtp-sdp")) {
    std::ifstream in(flags.GetString("rtp-sdp"), std::ios::binary);
    if (!in) return Fail("create", "cannot read " + flags.GetString("rtp-sdp"), 2);
    std::ostringstream sdp;
    sdp << in.rdbuf();
    request.mutable_rtp_sdp()->set_sdp(sdp.str());
    request.mutable_rtp_sdp()->set_start_timeout_ms(static_cast<int>(*start_ms));
    request.mutable_rtp_sdp()->set_receive_timeout_ms(static_cast<int>(*receive_ms));
  } else {
    request.mutable_upload();
  }
  *request.mutable_intrinsics() = api::IntrinsicsToProto(*k);
  v1::PipelineOptions* po = request.mutable_pipeline_options();
  auto eps = flags.GetDouble("eps-h", 0, 100);
  if (!eps.ok()) return Fail("create", eps.status().message(), 2);
  po->set_eps_h_px(*eps);
  int scale_sources = 0;
  if (flags.Has("first-step-m")) {
    auto v = flags.GetDouble("first-step-m", 1e-3, 1e3);
    if (!v.ok()) return Fail("create", v.status().message(), 2);
    po->set_scale_source(v1::PipelineOptions::FIRST_STEP);
    po->set_first_step_m(*v);
    ++scale_sources;
  }
  if (flags.Has("speed-kmh")) {
    auto v = flags.GetDouble("speed-kmh", 0.1, 500);
    if (!v.ok()) return Fail("create", v.status().message(), 2);
    po->set_scale_source(v1::PipelineOptions::SPEED);
    po->set_speed_mps(*v / 3.6);
    ++scale_sources;
  }
  if (flags.Has("camera-height-m")) {
    auto v = flags.GetDouble("camera-height-m", 0.05, 100);
    if (!v.ok()) return Fail("create", v.status().message(), 2);
    po->set_scale_source(v1::PipelineOptions::CAMERA_HEIGHT);
    po->set_camera_height_m(*v);
    ++scale_sources;
  }
  if (scale_sources > 1) return Fail("create", "give at most one scale source", 2);
  auto session = Connect(flags)->CreateSession(request);
  if (!session.ok()) return Fail("create", session.status().ToString());
  std::printf("%s\n", session->name().c_str());
  if (!session->ingest_url().empty()) std::printf("%s\n", session->ingest_url().c_str());
  return 0;
}

int RunUpload(int argc, char** argv) {
  Flags flags("upload", "SESSION FILE   (sends FILE as the session's stream)", {kServerFlag});
  if (int rc = ParseOrExit(flags, "upload", argc, argv, 2); rc >= 0) return rc;
  auto session = Connect(flags)->UploadFile(flags.positional()[0], flags.positional()[1]);
  if (!session.ok()) return Fail("upload", session.status().ToString());
  PrintSessionLine(*session);
  return 0;
}

int RunWatch(int argc, char** argv) {
  Flags flags("watch", "SESSION [options]   (until the session ends; resume with --after)",
              {kServerFlag,
               {"after", "N", "only events after sequence N", "0"},
               {"json", "", "one JSON object per line", ""}});
  if (int rc = ParseOrExit(flags, "watch", argc, argv, 1); rc >= 0) return rc;
  auto after = flags.GetInt("after", 0, INT64_MAX);
  if (!after.ok()) return Fail("watch", after.status().message(), 2);
  const bool json = flags.GetBool("json");
  Status s = Connect(flags)->Watch(
      flags.positional()[0], static_cast<uint64_t>(*after), [&](const v1::SessionEvent& e) {
        if (json) {
          std::printf("%s\n", Json(e).c_str());
        } else if (e.has_pose()) {
          const v1::PoseUpdate& p = e.pose();
          const v1::Pose& t = p.world_from_cam();
          std::printf(
              "%6llu pose   frame %-5lld t %7.3f s  %s  t = (%.3f, %.3f, %.3f)  q = (%.4f, "
              "%.4f, %.4f, %.4f)%s%s\n",
              static_cast<unsigned long long>(e.sequence()),
              static_cast<long long>(p.anchor_index()), p.timestamp_s(),
              p.tracking() ? "tracking" : "waiting ", t.tx(), t.ty(), t.tz(), t.qx(), t.qy(),
              t.qz(), t.qw(), p.note().empty() ? "" : "  ", p.note().c_str());
        } else if (e.has_plane()) {
          const v1::PlaneEvent& p = e.plane();
          std::printf("%6llu plane  %-8s track %-4d n = (%.3f, %.3f, %.3f)  d = %.3f\n",
                      static_cast<unsigned long long>(e.sequence()),
                      v1::PlaneEvent::Kind_Name(p.kind()).c_str(), p.track_id(),
                      p.normal_world().x(), p.normal_world().y(), p.normal_world().z(),
                      p.distance());
        } else if (e.has_reconnecting()) {
          const v1::Reconnecting& r = e.reconnecting();
          std::printf("%6llu reconnecting (attempt %d of %d) in %d ms: %s\n",
                      static_cast<unsigned long long>(e.sequence()), r.attempt(), r.max_attempts(),
                      r.delay_ms(), r.reason().c_str());
        } else if (e.has_state_change()) {
          std::printf("%6llu state  %s  %s\n", static_cast<unsigned long long>(e.sequence()),
                      StateName(e.state_change().state()), e.state_change().message().c_str());
        }
        std::fflush(stdout);
        return true;
      });
  if (!s.ok()) return Fail("watch", s.ToString());
  return 0;
}

int RunList(int argc, char** argv) {
  Flags flags(
      "list", "[options]",
      {kServerFlag, {"state", "STATE", "only CREATED, RUNNING, FINISHED, FAILED or STOPPED", ""}});
  if (int rc = ParseOrExit(flags, "list", argc, argv, 0); rc >= 0) return rc;
  v1::Session::State state = v1::Session::STATE_UNSPECIFIED;
  if (flags.Has("state") && !v1::Session::State_Parse(flags.GetString("state"), &state)) {
    return Fail("list", "unknown --state '" + flags.GetString("state") + "'", 2);
  }
  auto c = Connect(flags);
  std::string token;
  do {
    auto page = c->ListSessions(100, token, state);
    if (!page.ok()) return Fail("list", page.status().ToString());
    for (const v1::Session& s : page->sessions()) PrintSessionLine(s);
    token = page->next_page_token();
  } while (!token.empty());
  return 0;
}

int RunGet(int argc, char** argv) {
  Flags flags("get", "SESSION [options]", {kServerFlag, {"json", "", "the session as JSON", ""}});
  if (int rc = ParseOrExit(flags, "get", argc, argv, 1); rc >= 0) return rc;
  auto s = Connect(flags)->GetSession(flags.positional()[0]);
  if (!s.ok()) return Fail("get", s.status().ToString());
  if (flags.GetBool("json")) {
    std::printf("%s\n", Json(*s).c_str());
  } else {
    PrintSessionLine(*s);
  }
  return 0;
}

int RunStop(int argc, char** argv) {
  Flags flags("stop", "SESSION   (ends it STOPPED; results are kept)", {kServerFlag});
  if (int rc = ParseOrExit(flags, "stop", argc, argv, 1); rc >= 0) return rc;
  auto s = Connect(flags)->StopSession(flags.positional()[0]);
  if (!s.ok()) return Fail("stop", s.status().ToString());
  PrintSessionLine(*s);
  return 0;
}

int RunDelete(int argc, char** argv) {
  Flags flags("delete", "SESSION   (stops it and forgets it)", {kServerFlag});
  if (int rc = ParseOrExit(flags, "delete", argc, argv, 1); rc >= 0) return rc;
  Status s = Connect(flags)->DeleteSession(flags.positional()[0]);
  if (!s.ok()) return Fail("delete", s.ToString());
  return 0;
}

}  // namespace slapse::cli
