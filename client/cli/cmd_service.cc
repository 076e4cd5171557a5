// The slapse service from the command line: `serve` runs the gRPC server;
// create, upload, watch, list, get, stop and delete talk to one (--server).
#include <signal.h>

#include <google/protobuf/util/json_util.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "api/convert.h"
#include "api/list_query.h"
#include "api/validate.h"
#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "client/lib/client.h"
#include "core/common/intrinsics_io.h"
#include "core/planes/plane_extraction.h"
#include "server/log.h"
#include "server/server.h"
#include "server/udp_ports.h"

namespace slapse::cli {
namespace {

// Parses; returns -1 to go on, else the exit code (help printed or usage error).
int ParseOrExit(CommandLine& cl, int argc, char** argv, size_t positional) {
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  if (cl.positional().size() != positional) {
    return Fail(cl.command(),
                "expected " + std::to_string(positional) + " argument(s) (see --help)", 2);
  }
  return -1;
}

// A client of `server` as the connection flags say (AddServerFlag); a bad
// flag (unreadable CA, ...) ends the process with the usage error.
std::unique_ptr<client::SlapseClient> Connect(const std::string& server,
                                              double watch_timeout_s = 0) {
  auto o = ServerConnection();
  if (!o.ok()) std::exit(Fail("client", o.status().message(), 2));
  o->watch_timeout_s = watch_timeout_s;
  return client::SlapseClient::Connect(server, *o);
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
    case v1::Session::EXPIRED:
      return "EXPIRED";
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
  if (!s.labels().empty() || !s.stream_report().codec().empty()) {
    // Labels in key order, so the line is stable.
    std::map<std::string, std::string> sorted(s.labels().begin(), s.labels().end());
    std::string line =
        s.stream_report().codec().empty() ? "" : "codec " + s.stream_report().codec();
    for (const auto& [k, v] : sorted) line += (line.empty() ? "" : "  ") + k + "=" + v;
    std::printf("%-14s %s\n", "", line.c_str());
  }
  // A finished session without poses says why.
  if (s.state() == v1::Session::FINISHED && !s.state_message().empty()) {
    std::printf("%-14s %s\n", "", s.state_message().c_str());
  }
}

// `upload` and `watch`: the session ended FAILED.
constexpr int kExitSessionFailed = 3;

}  // namespace

int RunServe(int argc, char** argv) {
  CommandLine cl("serve", "[options]   (runs until SIGINT or SIGTERM, then shuts down gracefully)");
  CLI::App& app = cl.app();
  server::ServerOptions o;
  o.address = "";  // chosen after parsing: see --address
  int64_t port = o.port, max_sessions = o.sessions.max_sessions;
  int64_t max_upload_mb = o.sessions.max_upload_bytes >> 20;
  int64_t ring = static_cast<int64_t>(o.sessions.event_ring_capacity);
  app.add_option("--address", o.address,
                 "address to listen on (default: 0.0.0.0 when TLS and --tokens-file are both "
                 "given or with --insecure, else 127.0.0.1 only; any non-loopback address "
                 "without them is refused)")
      ->type_name("ADDR");
  app.add_option("--port", port, "TCP port (0: pick a free one)")
      ->type_name("PORT")
      ->capture_default_str();
  app.add_option("--max-sessions", max_sessions, "sessions active at once (worker threads)")
      ->type_name("N")
      ->capture_default_str();
  app.add_option("--max-upload-mb", max_upload_mb, "bytes one upload may send, MiB (0: no limit)")
      ->type_name("MB")
      ->capture_default_str();
  app.add_option("--event-ring", ring, "events kept per session for resuming watchers")
      ->type_name("N")
      ->capture_default_str();
  int64_t probe_kb = o.sessions.reader_probe_bytes >> 10;
  app.add_option("--reader-probe-kb", probe_kb,
                 "KiB a session's reader may read to identify its stream (FFmpeg's probesize; "
                 "MPEG-TS byte streams, RTSP push and upload, buffer this much at their start; "
                 "raise it for a stream whose facts come late; 0: FFmpeg's 5 MB)")
      ->type_name("KB")
      ->capture_default_str();
  app.add_option("--malloc-arena-max", o.malloc_arena_max,
                 "glibc malloc arenas of the process (fewer keep less freed memory per "
                 "session thread; 0: glibc's default, 8 per core)")
      ->type_name("N")
      ->capture_default_str();
  int64_t create_idle_s = o.sessions.create_idle_timeout_ms / 1000;
  int64_t stall_s = o.sessions.upload_stall_timeout_ms / 1000;
  app.add_option("--create-idle-timeout-s", create_idle_s,
                 "an upload session whose upload has not begun this long after its creation "
                 "ends FAILED (DEADLINE_EXCEEDED), freeing its worker (0: never)")
      ->type_name("S")
      ->capture_default_str();
  app.add_option("--upload-stall-timeout-s", stall_s,
                 "an upload that sends no bytes for this long ends its session FAILED "
                 "(DEADLINE_EXCEEDED), freeing its worker (0: never)")
      ->type_name("S")
      ->capture_default_str();
  o.sessions.rtsp_push_host.clear();  // unset: the gRPC --address
  app.add_option("--rtsp-host", o.sessions.rtsp_push_host,
                 "address the RTSP ingest port binds and ingest URLs name (default: --address)")
      ->type_name("IPV4");
  app.add_option("--rtsp-url-host", o.sessions.rtsp_url_host,
                 "the host ingest URLs name, when cameras reach the RTSP port by another name "
                 "than --rtsp-host (a pod's stable DNS name, a per-replica load balancer, NAT): "
                 "a DNS name or an IPv4 address (default: --rtsp-host)")
      ->type_name("HOST");
  int64_t rtsp_port = 8554;  // the CLI's fixed, documented port (docs/DEPLOY.md)
  app.add_option("--rtsp-port", rtsp_port,
                 "the one RTSP ingest port of every RTSP push session: publishers ANNOUNCE / "
                 "RECORD at /sessions/ID/PATH with the session's credentials (0: a free port)")
      ->type_name("PORT")
      ->capture_default_str();
  std::string rtp_ports = o.sessions.rtp_ports.ToString();
  app.add_option("--rtp-ports", rtp_ports,
                 "UDP ports RTP arrives on, MIN-MAX (MIN even, MAX odd): an RTP/SDP session's "
                 "m=video port must lie in it, and RTSP publishers recording over UDP get their "
                 "server ports from it; publish exactly this range from a container ('any': "
                 "no range)")
      ->type_name("RANGE")
      ->capture_default_str();
  // serve persists by default; the library's default (in memory) is for
  // tests and embedding.
  o.sessions.data_dir = server::DefaultDataDir();
  app.add_option("--data-dir", o.sessions.data_dir,
                 "where sessions and results persist (SQLite, slapse.db); ':memory:' keeps "
                 "them in memory only (nothing survives a restart)")
      ->type_name("DIR")
      ->capture_default_str();
  int64_t retention_ttl_s = o.sessions.retention_ttl_s;
  app.add_option("--retention-ttl-s", retention_ttl_s,
                 "a finished session's results are deleted this long after it ended (it "
                 "becomes EXPIRED; 0: kept until deleted)")
      ->type_name("S")
      ->capture_default_str();
  int64_t retention_max_store_mb = o.sessions.retention_max_store_bytes >> 20;
  app.add_option("--retention-max-store-mb", retention_max_store_mb,
                 "a size budget for the store, MiB of data (/metrics slapse_store_bytes): while "
                 "over it, the finished sessions whose end is oldest are EXPIRED (results "
                 "deleted) until it is under; active sessions are never touched (0: no budget)")
      ->type_name("MB")
      ->capture_default_str();
  app.add_option("--tls-cert", o.auth.tls_cert_file,
                 "server certificate chain (PEM); with --tls-key the server speaks TLS only "
                 "(gRPC, and HTTPS on --http-port)")
      ->type_name("FILE");
  app.add_option("--tls-key", o.auth.tls_key_file, "the certificate's private key (PEM)")
      ->type_name("FILE");
  app.add_option("--tls-client-ca", o.auth.tls_client_ca_file,
                 "CA bundle (PEM): clients must present a certificate it signed (mTLS)")
      ->type_name("FILE");
  app.add_option("--tokens-file", o.auth.tokens_file,
                 "bearer tokens -> tenants (JSON, see README 'Secure setup'); every rpc needs "
                 "a token and a tenant sees only its sessions; re-read when it changes and on "
                 "SIGHUP (default: $SLAPSE_TOKENS_FILE)")
      ->type_name("FILE");
  app.add_option("--tokens-reload-ms", o.auth.tokens_reload_interval_ms,
                 "how often the tokens file is checked for a change, ms (0: at every rpc)")
      ->type_name("MS")
      ->capture_default_str();
  app.add_flag("--insecure", o.auth.allow_insecure,
               "allow a non-loopback --address without TLS and tokens (anyone who reaches the "
               "port can read, stop and delete every session)");
  int64_t http_port = 8080;  // the CLI's fixed, documented port (docs/DEPLOY.md)
  app.add_option("--http-port", http_port,
                 "HTTP port for /metrics (Prometheus), /healthz and the dashboard, same address "
                 "(0: off; HTTPS with --tls-cert)")
      ->type_name("PORT")
      ->capture_default_str();
  app.add_flag("--reflection,!--no-reflection", o.reflection,
               "serve gRPC reflection (grpcurl and the like can list the rpcs)")
      ->capture_default_str();
  std::string log_format = "text";
  app.add_option("--log-format", log_format,
                 "stderr log: text, or json (JSON lines: time, level, session, event, message)")
      ->type_name("FORMAT")
      ->capture_default_str();
  app.add_option("--replica-id", o.sessions.replica_id,
                 "this server's name in a cluster (a DNS label, e.g. the StatefulSet pod "
                 "name): session names become sessions/<ID>-<random> so a proxy routes by "
                 "the x-slapse-replica header (docs/DEPLOY.md; default: none, one server)")
      ->type_name("ID");
  std::string peers;
  app.add_option("--peers", peers,
                 "the cluster's replicas, host:port,... (this one may be listed): "
                 "ListSessions asks them all and names the unreachable ones; needs --replica-id")
      ->type_name("LIST");
  app.add_option("--peer-tls-ca", o.peer_tls_ca_file,
                 "with TLS: CA bundle (PEM) that signed the peers' certificates (default: the "
                 "system's roots)")
      ->type_name("FILE");
  app.add_option("--peer-timeout-s", o.peer_timeout_s,
                 "how long ListSessions waits for each peer, s")
      ->type_name("S")
      ->capture_default_str();
  if (int rc = ParseOrExit(cl, argc, argv, 0); rc >= 0) return rc;
  o.peers = server::SplitPeerList(peers);
  server::LogOptions log_options;
  if (std::string error; !server::ParseLogFormat(log_format, &log_options.format, &error)) {
    return Fail("serve", "--" + error, 2);
  }
  if (Status s = CheckRange("http-port", http_port, int64_t{0}, int64_t{65535}); !s.ok()) {
    return Fail("serve", s.message(), 2);
  }
  o.http_port = static_cast<int>(http_port);
  server::ConfigureLog(log_options);
  if (o.auth.tokens_file.empty()) {
    const char* env = std::getenv("SLAPSE_TOKENS_FILE");
    if (env != nullptr) o.auth.tokens_file = env;
  }
  if (o.address.empty()) {
    const bool protected_ = o.auth.tls() && o.auth.tokens();
    o.address = protected_ || o.auth.allow_insecure ? "0.0.0.0" : "127.0.0.1";
  }
  for (const Status& s :
       {CheckRange("retention-ttl-s", retention_ttl_s, int64_t{0}, int64_t{1} << 40),
        CheckRange("retention-max-store-mb", retention_max_store_mb, int64_t{0}, int64_t{1} << 30),
        CheckRange("port", port, int64_t{0}, int64_t{65535}),
        CheckRange("rtsp-port", rtsp_port, int64_t{0}, int64_t{65535}),
        CheckRange("tokens-reload-ms", o.auth.tokens_reload_interval_ms, int64_t{0},
                   int64_t{1} << 31),
        CheckRange("max-sessions", max_sessions, int64_t{1}, int64_t{1024}),
        CheckRange("max-upload-mb", max_upload_mb, int64_t{0}, int64_t{1} << 30),
        CheckRange("event-ring", ring, int64_t{1}, int64_t{1} << 24),
        CheckRange("create-idle-timeout-s", create_idle_s, int64_t{0}, int64_t{1} << 31),
        CheckRange("upload-stall-timeout-s", stall_s, int64_t{0}, int64_t{1} << 31)}) {
    if (!s.ok()) return Fail("serve", s.message(), 2);
  }
  auto rtp_range = server::ParseUdpPortRange(rtp_ports);
  if (!rtp_range.ok()) return Fail("serve", "--rtp-ports: " + rtp_range.status().message(), 2);
  o.sessions.rtp_ports = *rtp_range;
  o.port = static_cast<int>(port);
  o.sessions.max_sessions = static_cast<int>(max_sessions);
  o.sessions.max_upload_bytes = max_upload_mb << 20;
  o.sessions.event_ring_capacity = static_cast<size_t>(ring);
  o.sessions.reader_probe_bytes = probe_kb << 10;
  o.sessions.create_idle_timeout_ms = create_idle_s * 1000;
  o.sessions.upload_stall_timeout_ms = stall_s * 1000;
  o.sessions.retention_ttl_s = retention_ttl_s;
  o.sessions.retention_max_store_bytes = retention_max_store_mb << 20;
  o.sessions.rtsp_port = static_cast<int>(rtsp_port);
  if (o.sessions.rtsp_push_host.empty()) o.sessions.rtsp_push_host = o.address;

  // Block the shutdown signals before gRPC starts its threads; wait for them below.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGHUP);  // re-read the tokens file
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto server = server::SlapseServer::Start(o);
  if (!server.ok()) return Fail("serve", server.status().message());
  std::printf(
      "slapse serving on %s:%d (max %d sessions; data in %s; %s; %s; health%s on)\n",
      o.address.c_str(), (*server)->port(), o.sessions.max_sessions, o.sessions.data_dir.c_str(),
      o.auth.tls() ? (o.auth.tls_client_ca_file.empty() ? "TLS" : "TLS with client certificates")
                   : "plain text",
      o.auth.tokens() ? "bearer tokens required" : "no tokens",
      o.reflection ? " + reflection" : "");
  if ((*server)->http_port() != 0) {
    std::printf("slapse metrics on http://%s:%d/metrics\n", o.address.c_str(),
                (*server)->http_port());
  }
  std::printf("slapse RTSP ingest on rtsp://%s:%d (RTP over UDP on ports %s%s%s)\n",
              o.sessions.rtsp_push_host.c_str(), (*server)->sessions().rtsp_port(),
              o.sessions.rtp_ports.ToString().c_str(),
              o.sessions.rtsp_url_host.empty() ? "" : "; URLs name ",
              o.sessions.rtsp_url_host.c_str());
  std::fflush(stdout);
  server::Log(server::LogLevel::kInfo, "", "serve",
              "gRPC on " + o.address + ":" + std::to_string((*server)->port()) +
                  ((*server)->http_port() != 0
                       ? ", HTTP on " + o.address + ":" + std::to_string((*server)->http_port())
                       : std::string(", no HTTP")));
  int sig = 0;
  while (sigwait(&signals, &sig) == 0 && sig == SIGHUP) {
    const Status reloaded = (*server)->ReloadTokens();
    if (reloaded.ok())
      server::Log(server::LogLevel::kInfo, "", "tokens", "SIGHUP: tokens reloaded");
  }
  server::Log(server::LogLevel::kInfo, "", "shutdown",
              std::string(sig == SIGINT ? "SIGINT" : "SIGTERM") + ", shutting down");
  (*server)->Shutdown();
  return 0;
}

namespace {

// `create`'s source and network flags, bound by AddSourceFlags.
struct SourceFlags {
  std::string rtsp_pull, rtsp_push, rtp_sdp;
  bool upload = false;
  int64_t start_timeout_ms = 0, receive_timeout_ms = 0;
  int64_t reconnect_attempts = 0, reconnect_interval_ms = 0, reconnect_max_interval_ms = 0;
  double reconnect_backoff = 0;
  std::vector<std::string> allow_senders;  // RtpSdp.allowed_senders
};

void AddSourceFlags(CLI::App& app, SourceFlags* f) {
  app.add_flag("--upload", f->upload, "the stream comes through 'slapse upload'");
  app.add_option("--rtsp-pull", f->rtsp_pull,
                 "the server pulls rtsp[s]://[user:pass@]host[:port]/path (over TCP)")
      ->type_name("URL");
  app.add_option("--rtsp-push", f->rtsp_push,
                 "a camera publishes (RTSP ANNOUNCE/RECORD) to the printed URL")
      ->type_name("PATH");
  app.add_option("--rtp-sdp", f->rtp_sdp,
                 "the server receives the RTP that this SDP file describes")
      ->type_name("FILE");
  app.add_option("--allow-sender", f->allow_senders,
                 "with --rtp-sdp: accept RTP from this IPv4/IPv6 address only (repeatable; "
                 "default: any sender)")
      ->type_name("ADDR");
  // 0 = the server's default (the request's proto fields say so).
  app.add_option("--start-timeout-ms", f->start_timeout_ms,
                 "network sources: wait for the first frame (0: 60000)")
      ->type_name("MS")
      ->capture_default_str();
  app.add_option("--receive-timeout-ms", f->receive_timeout_ms,
                 "network sources: wait between frames (0: 5000)")
      ->type_name("MS")
      ->capture_default_str();
  app.add_option("--reconnect-attempts", f->reconnect_attempts,
                 "--rtsp-pull: retries per outage (camera lost: connection closed or silent; "
                 "unreachable; 0: none); a camera that ends its stream finishes the session")
      ->type_name("N")
      ->capture_default_str();
  app.add_option("--reconnect-interval-ms", f->reconnect_interval_ms,
                 "--rtsp-pull: wait before the first retry (0: 1000)")
      ->type_name("MS")
      ->capture_default_str();
  app.add_option("--reconnect-backoff", f->reconnect_backoff,
                 "--rtsp-pull: each further wait is X times longer (0: 2)")
      ->type_name("X")
      ->capture_default_str();
  app.add_option("--reconnect-max-interval-ms", f->reconnect_max_interval_ms,
                 "--rtsp-pull: longest wait (0: 30000)")
      ->type_name("MS")
      ->capture_default_str();
}

// Fills the request's source from the flags; INVALID_ARGUMENT is a usage error.
Status SetSource(const CommandLine& cl, const SourceFlags& f, v1::Session* request) {
  const int sources = f.upload + cl.Has("rtsp-pull") + cl.Has("rtsp-push") + cl.Has("rtp-sdp");
  if (sources != 1) {
    return InvalidArgumentError(
        "give one source: --upload, --rtsp-pull URL, --rtsp-push PATH or --rtp-sdp FILE");
  }
  if (!f.allow_senders.empty() && !cl.Has("rtp-sdp")) {
    return InvalidArgumentError("--allow-sender is for --rtp-sdp sessions");
  }
  SLAPSE_RETURN_IF_ERROR(
      CheckRange("start-timeout-ms", f.start_timeout_ms, int64_t{0}, int64_t{3600000}));
  SLAPSE_RETURN_IF_ERROR(
      CheckRange("receive-timeout-ms", f.receive_timeout_ms, int64_t{0}, int64_t{3600000}));
  const int start_ms = static_cast<int>(f.start_timeout_ms);
  const int receive_ms = static_cast<int>(f.receive_timeout_ms);
  if (cl.Has("rtsp-pull")) {
    // Ranges are the server's (it answers INVALID_ARGUMENT with the reason).
    SLAPSE_RETURN_IF_ERROR(
        CheckRange("reconnect-attempts", f.reconnect_attempts, int64_t{0}, int64_t{INT32_MAX}));
    SLAPSE_RETURN_IF_ERROR(CheckRange("reconnect-interval-ms", f.reconnect_interval_ms, int64_t{0},
                                      int64_t{INT32_MAX}));
    SLAPSE_RETURN_IF_ERROR(CheckRange("reconnect-backoff", f.reconnect_backoff, 0, 1e9));
    SLAPSE_RETURN_IF_ERROR(CheckRange("reconnect-max-interval-ms", f.reconnect_max_interval_ms,
                                      int64_t{0}, int64_t{INT32_MAX}));
    v1::RtspPull* pull = request->mutable_rtsp_pull();
    pull->set_url(f.rtsp_pull);
    pull->set_start_timeout_ms(start_ms);
    pull->set_receive_timeout_ms(receive_ms);
    pull->mutable_reconnect()->set_max_attempts(static_cast<int>(f.reconnect_attempts));
    pull->mutable_reconnect()->set_initial_interval_ms(static_cast<int>(f.reconnect_interval_ms));
    pull->mutable_reconnect()->set_backoff_multiplier(f.reconnect_backoff);
    pull->mutable_reconnect()->set_max_interval_ms(static_cast<int>(f.reconnect_max_interval_ms));
  } else if (cl.Has("rtsp-push")) {
    request->mutable_rtsp_push()->set_path(f.rtsp_push);
    request->mutable_rtsp_push()->set_start_timeout_ms(start_ms);
    request->mutable_rtsp_push()->set_receive_timeout_ms(receive_ms);
  } else if (cl.Has("rtp-sdp")) {
    std::ifstream in(f.rtp_sdp, std::ios::binary);
    if (!in) return InvalidArgumentError("cannot read " + f.rtp_sdp);
    std::ostringstream sdp;
    sdp << in.rdbuf();
    request->mutable_rtp_sdp()->set_sdp(sdp.str());
    request->mutable_rtp_sdp()->set_start_timeout_ms(start_ms);
    request->mutable_rtp_sdp()->set_receive_timeout_ms(receive_ms);
    for (const std::string& a : f.allow_senders) request->mutable_rtp_sdp()->add_allowed_senders(a);
  } else {
    request->mutable_upload();
  }
  return Status::Ok();
}

// --intrinsics for a session: FILE.json or 'fx,fy,cx,cy' (the stream size is not known here).
StatusOr<Intrinsics> SessionIntrinsics(const std::string& spec) {
  if (spec.empty()) return InvalidArgumentError("--intrinsics is required");
  if (spec.rfind("hfov=", 0) == 0) {
    return InvalidArgumentError("hfov= needs the stream size; give FILE.json or 'fx,fy,cx,cy'");
  }
  return spec.size() > 5 && spec.substr(spec.size() - 5) == ".json"
             ? ReadIntrinsicsJson(spec)
             : ParseIntrinsicsSpec(spec, 0, 0);
}

}  // namespace

int RunCreate(int argc, char** argv) {
  CommandLine cl(
      "create",
      "--upload|--rtsp-pull URL|--rtsp-push PATH|--rtp-sdp FILE --intrinsics SPEC "
      "[options]\n  (prints the session name; for --rtsp-push also the URL to publish to)");
  CLI::App& app = cl.app();
  std::string server, intrinsics_spec;
  AddServerFlag(&cl, &server);
  SourceFlags source;
  AddSourceFlags(app, &source);
  app.add_option("--intrinsics", intrinsics_spec, "FILE.json or 'fx,fy,cx,cy' (pixels)")
      ->type_name("SPEC");
  // 0 asks for the server's default, which is this default.
  double eps_h_px = PlaneExtractionOptions{}.eps_h_px;
  app.add_option("--eps-h", eps_h_px, "homography inlier threshold (0: the server's default)")
      ->type_name("PX")
      ->capture_default_str();
  ScaleFlags scale_flags;
  scale_flags.AddTo(&cl);
  std::vector<std::string> labels;
  app.add_option("--label", labels, "a fleet label KEY=VALUE (repeatable), e.g. site=depot")
      ->type_name("KEY=VALUE");
  MvReaderOptions stream_options;
  bool no_reencode = !stream_options.reencode;
  app.add_flag("--no-reencode", no_reencode,
               "FAIL a stream whose codec has no motion vectors (HEVC, VP9, AV1, MJPEG, ...) "
               "instead of re-encoding it in-process");
  bool anchors_only = !PipelineOptions{}.frame_poses.enabled;
  app.add_flag("--anchors-only", anchors_only,
               "pose the anchor frames only (default: every frame between tracked anchors too)");
  if (int rc = ParseOrExit(cl, argc, argv, 0); rc >= 0) return rc;
  v1::Session request;
  if (Status s = SetSource(cl, source, &request); !s.ok()) return Fail("create", s.message(), 2);
  for (const std::string& label : labels) {
    const size_t eq = label.find('=');
    if (eq == std::string::npos || eq == 0) {
      return Fail("create", "--label wants KEY=VALUE, got '" + label + "'", 2);
    }
    (*request.mutable_labels())[label.substr(0, eq)] = label.substr(eq + 1);
  }
  if (Status s = api::ValidateLabels(request.labels()); !s.ok()) {
    return Fail("create", s.message(), 2);
  }
  StatusOr<Intrinsics> k = SessionIntrinsics(intrinsics_spec);
  if (!k.ok()) return Fail("create", k.status().message(), 2);
  *request.mutable_intrinsics() = api::IntrinsicsToProto(*k);
  if (Status s = CheckRange("eps-h", eps_h_px, 0, 100); !s.ok()) {
    return Fail("create", s.message(), 2);
  }
  // The options travel as core structs through the one conversion (api/convert.h);
  // eps_h 0 asks for the server's default.
  auto scale = scale_flags.Options();
  if (!scale.ok()) return Fail("create", scale.status().message(), 2);
  PipelineOptions options;
  options.extraction.eps_h_px = eps_h_px;
  options.scale = *scale;
  options.frame_poses.enabled = !anchors_only;
  *request.mutable_pipeline_options() = api::PipelineOptionsToProto(options);
  stream_options.reencode = !no_reencode;
  *request.mutable_stream_options() = api::StreamOptionsToProto(stream_options);
  auto session = Connect(server)->CreateSession(request);
  if (!session.ok()) return Fail("create", session.status().ToString());
  std::printf("%s\n", session->name().c_str());
  if (!session->ingest_url().empty()) {
    // RTSP push: the publish URL with the session's credentials, shown this
    // once (GetSession never returns them).
    const v1::RtspPublishCredentials& c = session->publish_credentials();
    std::printf(
        "%s\n",
        server::RtspPublishUrl(session->ingest_url(), {c.username(), c.password()}).c_str());
  }
  return 0;
}

int RunUpload(int argc, char** argv) {
  CommandLine cl("upload",
                 "SESSION FILE   (sends FILE as the session's stream; exit status 0: sent, 1: "
                 "the upload failed, 2: usage, 3: the session is FAILED)",
                 "SESSION FILE");
  std::string server;
  AddServerFlag(&cl, &server);
  if (int rc = ParseOrExit(cl, argc, argv, 2); rc >= 0) return rc;
  auto client = Connect(server);
  auto session = client->UploadFile(cl.positional()[0], cl.positional()[1]);
  if (!session.ok()) {
    // The rpc carries the session's own error when the session failed.
    auto now = client->GetSession(cl.positional()[0]);
    const bool failed = now.ok() && now->state() == v1::Session::FAILED;
    return Fail("upload", session.status().ToString(), failed ? kExitSessionFailed : 1);
  }
  PrintSessionLine(*session);
  if (session->state() == v1::Session::FAILED) {
    return Fail("upload", "the session is FAILED: " + session->error().message(),
                kExitSessionFailed);
  }
  return 0;
}

int RunWatch(int argc, char** argv) {
  CommandLine cl("watch",
                 "SESSION [options]   (until the session ends; resume with --after; exit status "
                 "0: the session ended FINISHED or STOPPED, 1: the watch failed, 2: usage, 3: "
                 "the session ended FAILED)",
                 "SESSION");
  v1::StateChange last_state;
  std::string server;
  AddServerFlag(&cl, &server);
  int64_t after = 0;
  bool json = false;
  cl.app()
      .add_option("--after", after, "only events after sequence N")
      ->type_name("N")
      ->capture_default_str();
  cl.app().add_flag("--json", json, "one JSON object per line");
  if (int rc = ParseOrExit(cl, argc, argv, 1); rc >= 0) return rc;
  if (Status s = CheckRange("after", after, int64_t{0}, INT64_MAX); !s.ok()) {
    return Fail("watch", s.message(), 2);
  }
  auto client = Connect(server);
  std::string last_scale_note;
  Status s = client->Watch(
      cl.positional()[0], static_cast<uint64_t>(after), [&](const v1::SessionEvent& e) {
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
          // The scale's state when it changes (it repeats while not observable yet).
          if (!p.scale_note().empty() && p.scale_note() != last_scale_note) {
            std::printf("       scale  %s\n", p.scale_note().c_str());
            last_scale_note = p.scale_note();
          }
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
          last_state = e.state_change();
          std::printf("%6llu state  %s  %s\n", static_cast<unsigned long long>(e.sequence()),
                      StateName(e.state_change().state()), e.state_change().message().c_str());
        }
        std::fflush(stdout);
        return true;
      });
  if (!s.ok()) return Fail("watch", s.ToString());
  if (last_state.state() == v1::Session::STATE_UNSPECIFIED) {
    // Resumed after the final event: the session says how it ended.
    auto now = client->GetSession(cl.positional()[0]);
    if (now.ok()) {
      last_state.set_state(now->state());
      last_state.set_message(now->state_message());
    }
  }
  if (last_state.state() == v1::Session::FAILED) {
    return Fail("watch", "the session ended FAILED: " + last_state.message(), kExitSessionFailed);
  }
  return 0;
}

int RunList(int argc, char** argv) {
  CommandLine cl("list", "[options]");
  std::string server, state_name;
  v1::ListSessionsRequest request;
  AddServerFlag(&cl, &server);
  cl.app()
      .add_option("--state", state_name, "only CREATED, RUNNING, FINISHED, FAILED or STOPPED")
      ->type_name("STATE");
  cl.app()
      .add_option("--filter", *request.mutable_filter(),
                  "AIP-160 filter, e.g. 'state=RUNNING AND labels.site=depot' "
                  "(fields: api/list_query.h)")
      ->type_name("EXPR");
  cl.app()
      .add_option("--order-by", *request.mutable_order_by(),
                  "e.g. 'stats.lag_ms desc, name' (default: create_time, name)")
      ->type_name("ORDER");
  if (int rc = ParseOrExit(cl, argc, argv, 0); rc >= 0) return rc;
  v1::Session::State state = v1::Session::STATE_UNSPECIFIED;
  if (cl.Has("state") && !v1::Session::State_Parse(state_name, &state)) {
    return Fail("list", "unknown --state '" + state_name + "'", 2);
  }
  request.set_state_filter(state);
  // The same parser as the server's: a bad expression is a usage error here.
  if (auto f = api::SessionFilter::Parse(request.filter()); !f.ok()) {
    return Fail("list", f.status().message(), 2);
  }
  if (auto o = api::SessionOrder::Parse(request.order_by()); !o.ok()) {
    return Fail("list", o.status().message(), 2);
  }
  auto c = Connect(server);
  request.set_page_size(100);
  do {
    auto page = c->ListSessions(request);
    if (!page.ok()) return Fail("list", page.status().ToString());
    for (const v1::Session& s : page->sessions()) PrintSessionLine(s);
    // A cluster's replicas that did not answer: their sessions are missing
    // (said once, on the first page).
    const bool first_page = request.page_token().empty();
    for (int i = 0; first_page && i < page->unreachable_peers_size(); ++i) {
      std::fprintf(stderr, "list: warning: not listed, a replica did not answer: %s\n",
                   page->unreachable_peers(i).c_str());
    }
    request.set_page_token(page->next_page_token());
  } while (!request.page_token().empty());
  return 0;
}

int RunGet(int argc, char** argv) {
  CommandLine cl("get", "SESSION [options]", "SESSION");
  std::string server;
  AddServerFlag(&cl, &server);
  bool json = false;
  cl.app().add_flag("--json", json, "the session as JSON");
  if (int rc = ParseOrExit(cl, argc, argv, 1); rc >= 0) return rc;
  auto s = Connect(server)->GetSession(cl.positional()[0]);
  if (!s.ok()) return Fail("get", s.status().ToString());
  if (json) {
    std::printf("%s\n", Json(*s).c_str());
  } else {
    PrintSessionLine(*s);
  }
  return 0;
}

int RunStop(int argc, char** argv) {
  CommandLine cl("stop", "SESSION   (ends it STOPPED; results are kept)", "SESSION");
  std::string server;
  AddServerFlag(&cl, &server);
  if (int rc = ParseOrExit(cl, argc, argv, 1); rc >= 0) return rc;
  auto s = Connect(server)->StopSession(cl.positional()[0]);
  if (!s.ok()) return Fail("stop", s.status().ToString());
  PrintSessionLine(*s);
  return 0;
}

int RunDelete(int argc, char** argv) {
  CommandLine cl("delete", "SESSION   (stops it and forgets it)", "SESSION");
  std::string server;
  AddServerFlag(&cl, &server);
  if (int rc = ParseOrExit(cl, argc, argv, 1); rc >= 0) return rc;
  Status s = Connect(server)->DeleteSession(cl.positional()[0]);
  if (!s.ok()) return Fail("delete", s.ToString());
  return 0;
}

}  // namespace slapse::cli
