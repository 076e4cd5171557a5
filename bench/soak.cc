// soak: live cameras and watchers against a real `slapse serve` process for a
// given time, with faults injected on a schedule (issue 17). Not a test:
// outside CI, it reports and its exit code says whether the invariants held.
//
//   build/bench/soak --cameras 4 --rtp-cameras 1 --duration-s 180
//   build/bench/soak --cameras 16 --rtp-cameras 4 --duration-s 3600 --json soak.jsonl
//
// Parts, all real: `slapse serve` (a separate process on a data directory, so
// it can be SIGKILLed and restarted), `ffmpeg -re -stream_loop` cameras
// publishing a simulated drive over RTSP push (TCP) or RTP (UDP, through a
// relay in this process that can drop packets), and watchers on the client
// library that resume from their cursor.
//
// A camera slot runs sessions back to back: create a session, start its
// watchers and its camera, which sends the drive --loops times and ends (RTSP:
// TEARDOWN -> FINISHED; RTP: silence -> FINISHED), then the next session.
// Faults, each on its own period (0 = off), the victim drawn with --seed:
//   camera kill     SIGKILL of a camera; its session ends (RTSP: FAILED lost,
//                   RTP: FINISHED short) and the slot starts a new session
//                   with a new camera after --camera-restart-s;
//   watcher drop    a watcher cancels its watch, waits --watcher-pause-s and
//                   resumes after the last sequence it saw;
//   server restart  SIGKILL of `slapse serve`, restarted on the same data dir
//                   and ports; RTSP cameras publish again to their session,
//                   watchers resume, RTP cameras never noticed;
//   RTP loss        the relay of an RTP camera drops --loss-rate of its RTP
//                   packets for --loss-burst-s.
//
// Reported (table on stdout, JSON lines with --json):
//   - RSS of the server process over time (/proc/<pid>/status), and per
//     server life the least-squares slope after --warmup-s (flat = ~0 MiB/h);
//   - per session: SessionStats.fps and lag_ms sampled each second while
//     RUNNING (after 1 s of stream), p50 / p95 / p99;
//   - per watcher: events delivered vs expected (1..Session.last_sequence at
//     the end), lost and repeated counted from the sequence numbers
//     (bench/soak_ledger.h);
//   - whole sessions compared with the offline run: a session is
//     *fault-free* when it ended FINISHED, its camera ran once from creation
//     to end (never killed, never republished), no server restart happened
//     between its creation and its end, and its relay (RTP) dropped no
//     packet; *whole* when fault-free and it decoded every frame the camera
//     sent (the offline run's frame count). A whole session's trajectory,
//     written as TUM by core/pipeline/result_io.h (as `slapse export` does),
//     must equal byte for byte the trajectory_tum.txt of `slapse run` on the
//     same bytes (the drive looped --loops times by `ffmpeg -stream_loop -c
//     copy`). A fault-free session that is short lost frames on the way
//     without an injected fault: reported with the drops the kernel counted
//     on the server's and the relay's UDP sockets (/proc/net/udp: a reader
//     fell behind and its receive buffer overflowed); short without such
//     drops is unexplained.
// Exit code 0 when no event was lost, repeated or unexpected, every whole
// session (at least one) equalled its offline run and no session was short
// unexplained; 1 otherwise.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "api/convert.h"
#include "bench/rss.h"
#include "bench/soak_ledger.h"
#include "bench/stats.h"
#include "client/lib/client.h"
#include "core/pipeline/result_io.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse::bench {
namespace {

using client::SlapseClient;
using Clock = std::chrono::steady_clock;
using Json = nlohmann::json;
using testing::FfmpegProcess;

struct SoakOptions {
  int cameras = 4;                  // camera slots
  int rtp_cameras = 1;              // of them, RTP (UDP through the relay); the rest RTSP push
  int watchers = 2;                 // watchers per session
  double duration_s = 180;          // faults and new sessions until then; then the last ones end
  double drive_s = 20;              // the simulated drive's length
  int loops = 2;                    // the drive sent this many times per session
  double camera_kill_every_s = 60;  // 0 = never
  double camera_restart_s = 2;
  double watcher_drop_every_s = 20;
  double watcher_pause_s = 2;
  double server_kill_every_s = 90;
  double loss_every_s = 45;
  double loss_burst_s = 5;
  double loss_rate = 0.05;
  double sample_s = 5;          // RSS sample period
  double warmup_s = 60;         // per server life, before the RSS slope counts
  double drain_s = 120;         // after duration_s, longest wait for the last sessions
  int64_t retention_ttl_s = 0;  // serve --retention-ttl-s (0: keep; bounds a day-long store)
  uint64_t seed = 1;
  std::string work_dir;   // default: a fresh temp dir
  std::string json_path;  // JSON lines; empty = none
  std::string slapse = SLAPSE_CLI;
};

// Soak time: from Soak::Run's start (the drive and the offline run before it
// do not count).
Clock::time_point g_start = Clock::now();
double NowS() { return std::chrono::duration<double>(Clock::now() - g_start).count(); }
void SleepS(double s) { std::this_thread::sleep_for(std::chrono::duration<double>(s)); }

bool Active(const v1::Session& s) {
  return s.state() == v1::Session::CREATED || s.state() == v1::Session::RUNNING;
}

// The kernel's drop count of the UDP sockets bound to local `port`
// (/proc/net/udp, last column): datagrams lost because the receive buffer was
// full, i.e. the reader fell behind.
int64_t UdpDrops(int port) {
  char want[8];
  std::snprintf(want, sizeof(want), ":%04X", port);
  int64_t drops = 0;
  std::ifstream in("/proc/net/udp");
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string slot, local, token, last;
    fields >> slot >> local;
    if (local.size() < 5 || local.compare(local.size() - 5, 5, want) != 0) continue;
    while (fields >> token) last = token;
    drops += std::atoll(last.c_str());
  }
  return drops;
}

// `slapse serve` on fixed ports and a data directory, restartable.
class ServeProcess : public testing::LoggedProcess {
 public:
  ServeProcess(const SoakOptions& o, int port, int rtsp_port, const std::string& log)
      : LoggedProcess(
            {o.slapse, "serve", "--address", "127.0.0.1", "--port", std::to_string(port),
             "--data-dir", o.work_dir + "/data", "--max-sessions", std::to_string(o.cameras + 2),
             "--http-port", "0", "--rtsp-port", std::to_string(rtsp_port), "--retention-ttl-s",
             std::to_string(o.retention_ttl_s)},
            log) {}
  pid_t pid() const { return pid_; }
};

// A UDP relay 127.0.0.1:port (RTP) and port + 1 (RTCP) -> the session's
// ports, dropping RTP packets at `rate` while a loss burst is on.
class RtpRelay {
 public:
  explicit RtpRelay(uint64_t seed) : rng_(seed) {
    port_ = testing::FreeRtpPort();
    for (int i = 0; i < 2; ++i) {
      fd_[i] = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
      sockaddr_in sa = Loopback(port_ + i);
      const int rcvbuf_bytes = 4 << 20;  // capped by net.core.rmem_max
      setsockopt(fd_[i], SOL_SOCKET, SO_RCVBUF, &rcvbuf_bytes, sizeof(rcvbuf_bytes));
      bind(fd_[i], reinterpret_cast<sockaddr*>(&sa), sizeof(sa));
    }
    thread_ = std::thread([this] { Loop(); });
  }
  ~RtpRelay() {
    stop_ = true;
    thread_.join();
    close(fd_[0]);
    close(fd_[1]);
  }
  int port() const { return port_; }
  void SetTarget(int port) { target_ = port; }
  void Burst(double until_s, double rate) {
    rate_ = rate;
    loss_until_s_ = until_s;
  }
  uint64_t dropped() const { return dropped_; }
  // Datagrams the kernel dropped on the relay's own RTP socket (its buffer
  // full: this process fell behind), so far.
  int64_t socket_drops() const { return UdpDrops(port_); }

 private:
  static sockaddr_in Loopback(int port) {
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    sa.sin_port = htons(static_cast<uint16_t>(port));
    return sa;
  }
  void Loop() {
    pollfd p[2] = {{fd_[0], POLLIN, 0}, {fd_[1], POLLIN, 0}};
    char buf[65536];
    std::uniform_real_distribution<double> u(0, 1);
    while (!stop_) {
      if (poll(p, 2, 100) <= 0) continue;
      for (int i = 0; i < 2; ++i) {
        if (!(p[i].revents & POLLIN)) continue;
        const ssize_t n = recv(fd_[i], buf, sizeof(buf), 0);
        if (n <= 0 || target_ <= 0) continue;
        if (i == 0 && NowS() < loss_until_s_ && u(rng_) < rate_) {
          ++dropped_;
          continue;
        }
        const sockaddr_in to = Loopback(target_ + i);
        sendto(fd_[i], buf, n, 0, reinterpret_cast<const sockaddr*>(&to), sizeof(to));
      }
    }
  }

  std::mt19937_64 rng_;
  int port_ = 0;
  int fd_[2] = {-1, -1};
  std::atomic<int> target_{0};
  std::atomic<double> rate_{0}, loss_until_s_{0};
  std::atomic<uint64_t> dropped_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

struct Watcher {
  SequenceLedger ledger;  // the watcher thread's until joined
  std::atomic<bool> drop{false};
  int drops = 0, retries = 0;
  Status end;
  std::thread thread;
};

// One session of a camera slot, from creation to its report.
struct Life {
  int camera = 0;
  bool rtp = false;
  v1::Session created;  // CreateSession's answer (the publish credentials)
  double created_s = 0, ended_s = 0;
  uint64_t epoch_at_create = 0, epoch_at_end = 0;
  uint64_t relay_dropped_at_create = 0, relay_dropped = 0;
  int rtp_port = 0;
  bool camera_killed = false;
  int camera_starts = 0;
  std::unique_ptr<FfmpegProcess> camera_process;
  std::vector<std::unique_ptr<Watcher>> watchers;
  std::vector<double> fps, lag_ms;
  v1::Session final;
  std::string offline = "-";     // "-" not whole, else "equal" or how it differs
  int64_t kernel_udp_drops = 0;  // RTP: the server socket's drops (/proc/net/udp)
  int64_t relay_socket_drops_at_create = 0, relay_socket_drops = 0;  // the relay's socket
  int64_t reference_frames = 0;  // the frames the camera sent (the offline run's)
  // No fault touched it: ended FINISHED, its camera ran once from creation to
  // end, no server restart in between, no packet dropped by the relay.
  bool fault_free() const {
    return final.state() == v1::Session::FINISHED && !camera_killed && camera_starts == 1 &&
           epoch_at_create == epoch_at_end && relay_dropped == 0;
  }
  // Whole: fault-free and every frame the camera sent was decoded.
  bool whole() const { return fault_free() && final.stats().frames() == reference_frames; }
  // Fault-free but short: frames lost on the way without an injected fault.
  bool short_stream() const { return fault_free() && !whole(); }
};

class Soak;

// A camera and its sessions, one after another, on a thread of its own.
class CameraSlot {
 public:
  CameraSlot(Soak* soak, int index, bool rtp);
  void Run();
  // Faults, from the scheduler thread; false when there was nothing to hit.
  bool KillCamera();
  bool DropWatcher(std::mt19937_64& rng);
  bool LossBurst(double until_s, double rate);
  bool rtp() const { return rtp_; }
  bool live() {
    std::lock_guard<std::mutex> lock(mu_);
    return life_ != nullptr;
  }

 private:
  bool Create(Life* life);
  void StartCamera(Life* life);
  void WatchLoop(const std::string& name, Watcher* w);
  void Monitor(Life* life);
  void End(Life* life);

  Soak* soak_;
  int index_;
  bool rtp_;
  std::unique_ptr<RtpRelay> relay_;
  std::mutex mu_;         // guards life_ (its camera and watchers) against the faults
  Life* life_ = nullptr;  // the session now running, if any
};

class Soak {
 public:
  Soak(SoakOptions o, testing::TestDrive drive, std::string reference_tum, int64_t reference_frames)
      : o_(std::move(o)),
        drive_(std::move(drive)),
        reference_tum_(std::move(reference_tum)),
        reference_frames_(reference_frames) {}
  int Run();

  const SoakOptions& options() const { return o_; }
  const testing::TestDrive& drive() const { return drive_; }
  SlapseClient& client() { return *client_; }
  SlapseClient& watch_client() { return *watch_client_; }
  int rtsp_port() const { return rtsp_port_; }
  uint64_t epoch() const { return epoch_; }
  bool stopping() const { return stopping_; }
  bool aborting() const { return aborting_; }
  bool give_up() const { return give_up_; }
  void Event(const std::string& text, Json j);
  void Report(Life* life);

 private:
  void StartServer();
  void RestartServer();
  void SampleRss();
  void InjectFaults(double now_s, std::vector<double>* next_s);
  void Drain();
  void CompareWithOffline(Life* life);
  int Summarise();
  void PrintSessions() const;
  void PrintRss() const;

  SoakOptions o_;
  testing::TestDrive drive_;
  std::string reference_tum_;
  int64_t reference_frames_ = 0;
  int port_ = 0, rtsp_port_ = 0;
  std::unique_ptr<ServeProcess> server_;
  double server_started_s_ = 0;
  std::atomic<uint64_t> epoch_{0};  // server lives
  std::unique_ptr<SlapseClient> client_, watch_client_;
  std::vector<std::unique_ptr<CameraSlot>> slots_;
  std::vector<std::thread> threads_;
  std::atomic<bool> stopping_{false}, aborting_{false}, give_up_{false};
  std::atomic<int> slots_done_{0};
  std::mt19937_64 rng_{1};
  std::ofstream json_;
  mutable std::mutex mu_;  // guards json_, lives_, rss_
  std::vector<std::unique_ptr<Life>> lives_;
  struct RssSample {
    double t_s;
    uint64_t life;
    double since_start_s, rss_mib;
    int sessions;
  };
  std::vector<RssSample> rss_;
  std::vector<double> life_start_s_;
  int faults_[4] = {0, 0, 0, 0};  // camera kills, watcher drops, server restarts, loss bursts
};

// ---------------------------------------------------------------- CameraSlot

CameraSlot::CameraSlot(Soak* soak, int index, bool rtp) : soak_(soak), index_(index), rtp_(rtp) {
  if (rtp_) relay_ = std::make_unique<RtpRelay>(soak->options().seed * 1000 + index);
}

void CameraSlot::Run() {
  while (!soak_->stopping()) {
    auto life = std::make_unique<Life>();
    life->camera = index_;
    life->rtp = rtp_;
    if (!Create(life.get())) {
      SleepS(1);
      continue;
    }
    for (int i = 0; i < soak_->options().watchers; ++i) {
      life->watchers.push_back(std::make_unique<Watcher>());
      Watcher* w = life->watchers.back().get();
      w->thread = std::thread([this, name = life->created.name(), w] { WatchLoop(name, w); });
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      StartCamera(life.get());
      life_ = life.get();
    }
    Monitor(life.get());
    End(life.get());
    const bool killed = life->camera_killed;
    soak_->Report(life.release());
    if (killed) SleepS(soak_->options().camera_restart_s);
  }
}

// CreateSession, retried while the server is down.
bool CameraSlot::Create(Life* life) {
  const SoakOptions& o = soak_->options();
  v1::Session req;
  *req.mutable_intrinsics() = api::IntrinsicsToProto(soak_->drive().intrinsics);
  (*req.mutable_labels())["soak_camera"] = std::to_string(index_);
  if (rtp_) {
    life->rtp_port = testing::FreeRtpPort();
    req.mutable_rtp_sdp()->set_sdp(testing::Mpeg2RtpSdp(life->rtp_port));
    req.mutable_rtp_sdp()->set_start_timeout_ms(30000);
    req.mutable_rtp_sdp()->set_receive_timeout_ms(3000);
  } else {
    req.mutable_rtsp_push()->set_path("cam" + std::to_string(index_));
    req.mutable_rtsp_push()->set_start_timeout_ms(30000);
    req.mutable_rtsp_push()->set_receive_timeout_ms(5000);
  }
  life->epoch_at_create = soak_->epoch();
  life->created_s = NowS();
  if (relay_) {
    life->relay_dropped_at_create = relay_->dropped();
    life->relay_socket_drops_at_create = relay_->socket_drops();
  }
  auto created = soak_->client().CreateSession(req);
  if (!created.ok()) {
    if (soak_->epoch() == life->epoch_at_create) {
      std::fprintf(stderr, "soak: camera %d: create: %s\n", index_,
                   created.status().ToString().c_str());
    }
    (void)o;
    return false;
  }
  life->created = *created;
  return true;
}

// Starts the camera (RTSP: to the session's publish URL; RTP: to the relay,
// once the server bound the session's port: UDP drops what comes early).
// Caller holds mu_.
void CameraSlot::StartCamera(Life* life) {
  const SoakOptions& o = soak_->options();
  std::vector<std::string> args = {
      "-re", "-stream_loop", std::to_string(o.loops - 1), "-i", soak_->drive().video_path,
      "-c",  "copy"};
  if (rtp_) {
    testing::WaitForLocalPort("udp", life->rtp_port, std::chrono::seconds(10));
    relay_->SetTarget(life->rtp_port);
    args.insert(args.end(), {"-f", "rtp", "rtp://127.0.0.1:" + std::to_string(relay_->port())});
  } else {
    testing::WaitForLocalPort("tcp", soak_->rtsp_port(), std::chrono::seconds(10));
    args.insert(args.end(),
                {"-f", "rtsp", "-rtsp_transport", "tcp", testing::PublishUrl(life->created)});
  }
  life->camera_process = std::make_unique<FfmpegProcess>(args);
  ++life->camera_starts;
}

// Resumes from the cursor after a drop (CANCELLED), a server restart or the
// watch deadline, until the session ended and every event came (OK).
void CameraSlot::WatchLoop(const std::string& name, Watcher* w) {
  for (;;) {
    bool dropped = false;
    w->end = soak_->watch_client().Watch(name, w->ledger.cursor(), [&](const v1::SessionEvent& e) {
      w->ledger.Deliver(e.sequence());
      dropped = w->drop.exchange(false);
      return !dropped && !soak_->give_up();
    });
    if (w->end.ok() || soak_->give_up()) return;
    if (w->end.code() == StatusCode::kNotFound || w->end.code() == StatusCode::kOutOfRange) return;
    if (dropped) {
      ++w->drops;
      SleepS(soak_->options().watcher_pause_s);
    } else {
      ++w->retries;
      SleepS(0.5);
    }
  }
}

// Polls the session until it ends: samples fps / lag each second, publishes
// again when an RTSP camera lost its server (restart) while the session lives.
void CameraSlot::Monitor(Life* life) {
  double next_sample_s = 0;
  for (;;) {
    SleepS(0.25);
    auto got = soak_->client().GetSession(life->created.name());
    if (!got.ok()) continue;  // the server is restarting
    life->final = *got;
    if (!Active(*got)) break;
    if (NowS() >= next_sample_s && got->state() == v1::Session::RUNNING &&
        got->stats().stream_time_s() >= 1.0) {
      life->fps.push_back(got->stats().fps());
      life->lag_ms.push_back(got->stats().lag_ms());
      next_sample_s = NowS() + 1.0;
      if (rtp_) {
        life->kernel_udp_drops = std::max(life->kernel_udp_drops, UdpDrops(life->rtp_port));
      }
    }
    std::lock_guard<std::mutex> lock(mu_);
    FfmpegProcess* cam = life->camera_process.get();
    if (rtp_ || life->camera_killed || cam == nullptr) continue;
    const int rc = cam->Wait(std::chrono::milliseconds(0));
    if (!cam->started() && rc != 0 && !soak_->aborting()) StartCamera(life);  // exited: lost
  }
}

// The session ended: its camera is reaped, its watchers joined (they end at
// the last event), the relay's drops counted.
void CameraSlot::End(Life* life) {
  life->ended_s = NowS();
  life->epoch_at_end = soak_->epoch();
  {
    std::lock_guard<std::mutex> lock(mu_);
    life_ = nullptr;
  }
  if (life->camera_process) {
    life->camera_process->Wait(std::chrono::seconds(10));
    life->camera_process.reset();
  }
  if (relay_) {
    relay_->SetTarget(0);
    life->relay_dropped = relay_->dropped() - life->relay_dropped_at_create;
    life->relay_socket_drops = relay_->socket_drops() - life->relay_socket_drops_at_create;
  }
  for (auto& w : life->watchers) w->thread.join();
  for (;;) {  // the final state and last_sequence, the server maybe restarting
    auto got = soak_->client().GetSession(life->created.name());
    if (got.ok()) {
      life->final = *got;
      break;
    }
    SleepS(0.5);
  }
}

bool CameraSlot::KillCamera() {
  std::lock_guard<std::mutex> lock(mu_);
  if (life_ == nullptr || life_->camera_process == nullptr || !life_->camera_process->started()) {
    return false;
  }
  life_->camera_process->Kill();
  life_->camera_killed = true;
  return true;
}

bool CameraSlot::DropWatcher(std::mt19937_64& rng) {
  std::lock_guard<std::mutex> lock(mu_);
  if (life_ == nullptr || life_->watchers.empty()) return false;
  life_->watchers[rng() % life_->watchers.size()]->drop = true;
  return true;
}

bool CameraSlot::LossBurst(double until_s, double rate) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!relay_ || life_ == nullptr) return false;
  relay_->Burst(until_s, rate);
  return true;
}

// ---------------------------------------------------------------------- Soak

void Soak::Event(const std::string& text, Json j) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!text.empty()) std::fprintf(stderr, "[%8.1f s] %s\n", NowS(), text.c_str());
  if (json_.is_open()) {
    j["t_s"] = NowS();
    json_ << j.dump() << "\n";
    json_.flush();
  }
}

void Soak::StartServer() {
  server_ = std::make_unique<ServeProcess>(o_, port_, rtsp_port_, o_.work_dir + "/serve.log");
  for (int i = 0; i < 600; ++i) {
    if (client_->ListSessions(1, "", v1::Session::STATE_UNSPECIFIED).ok()) break;
    SleepS(0.1);
  }
  server_started_s_ = NowS();
  std::lock_guard<std::mutex> lock(mu_);
  life_start_s_.push_back(server_started_s_);
}

void Soak::RestartServer() {
  server_->Kill();  // SIGKILL, reaped
  ++epoch_;
  Event("server killed (SIGKILL), restarting on " + o_.work_dir + "/data",
        {{"type", "fault"}, {"fault", "server_restart"}});
  SleepS(1);
  StartServer();
  Event("server serving again", {{"type", "server_up"}, {"life", epoch_.load()}});
}

void Soak::SampleRss() {
  const long kb = RssKbOf(server_->pid());
  RssSample r{NowS(), epoch_, NowS() - server_started_s_, kb / 1024.0, 0};
  for (auto& s : slots_) r.sessions += s->live();
  {
    std::lock_guard<std::mutex> lock(mu_);
    rss_.push_back(r);
  }
  Event("", {{"type", "rss"},
             {"server_life", r.life},
             {"since_server_start_s", r.since_start_s},
             {"rss_mib", r.rss_mib},
             {"live_sessions", r.sessions}});
}

void Soak::InjectFaults(double now_s, std::vector<double>* next_s) {
  const double every[4] = {o_.camera_kill_every_s, o_.watcher_drop_every_s, o_.server_kill_every_s,
                           o_.loss_every_s};
  for (int kind = 0; kind < 4; ++kind) {
    if (every[kind] <= 0 || now_s < (*next_s)[kind]) continue;
    (*next_s)[kind] += every[kind];
    if (kind == 2) {
      RestartServer();
      ++faults_[kind];
      continue;
    }
    // The victim: the first slot, from a random one on, that has something to hit.
    const size_t first = rng_() % slots_.size();
    for (size_t k = 0; k < slots_.size(); ++k) {
      CameraSlot& slot = *slots_[(first + k) % slots_.size()];
      const int cam = static_cast<int>((first + k) % slots_.size());
      bool hit = false;
      if (kind == 0) hit = slot.KillCamera();
      if (kind == 1) hit = slot.DropWatcher(rng_);
      if (kind == 3) hit = slot.LossBurst(now_s + o_.loss_burst_s, o_.loss_rate);
      if (!hit) continue;
      static const char* kNames[4] = {"camera_kill", "watcher_drop", "server_restart", "rtp_loss"};
      Event(std::string(kNames[kind]) + " on camera " + std::to_string(cam),
            {{"type", "fault"}, {"fault", kNames[kind]}, {"camera", cam}});
      ++faults_[kind];
      break;
    }
  }
}

// A whole session's trajectory as `slapse export --format tum` writes it,
// against `slapse run`'s file of the same bytes.
void Soak::CompareWithOffline(Life* life) {
  StatusOr<v1::Trajectory> got = Status(StatusCode::kUnavailable, "");
  for (int attempt = 0; attempt < 60 && !got.ok(); ++attempt) {
    got = client_->GetTrajectory(life->created.name());
    if (!got.ok()) SleepS(0.5);
  }
  if (!got.ok()) {
    life->offline = "no trajectory: " + got.status().ToString();
    return;
  }
  std::ostringstream tum;
  WriteTrajectoryTum(api::TrajectoryFromProto(*got), tum);
  if (tum.str() == reference_tum_) {
    life->offline = "equal";
    return;
  }
  std::istringstream a(tum.str()), b(reference_tum_);
  std::string la, lb;
  int lines = 0, differ = 0;
  while (std::getline(b, lb)) {
    ++lines;
    differ += !std::getline(a, la) || la != lb;
  }
  life->offline = "differs: " + std::to_string(differ) + " of " + std::to_string(lines) +
                  " lines (" + std::to_string(got->points_size()) + " poses)";
}

Json WatcherJson(const Watcher& w, uint64_t last_sequence) {
  const LedgerTally t = w.ledger.Against(last_sequence);
  return {{"expected", t.expected}, {"delivered", t.delivered},   {"lost", t.lost},
          {"repeated", t.repeated}, {"unexpected", t.unexpected}, {"drops", w.drops},
          {"retries", w.retries},   {"end", w.end.ToString()}};
}

void Soak::Report(Life* life_raw) {
  std::unique_ptr<Life> life(life_raw);
  life->reference_frames = reference_frames_;
  if (life->whole()) CompareWithOffline(life.get());
  if (life->short_stream()) {
    life->offline = "short: " + std::to_string(life->final.stats().frames()) + " of " +
                    std::to_string(reference_frames_) +
                    " frames, no fault injected (UDP socket drops: server " +
                    std::to_string(life->kernel_udp_drops) + ", relay " +
                    std::to_string(life->relay_socket_drops) + ")";
  }
  Json watchers = Json::array();
  for (const auto& w : life->watchers) {
    watchers.push_back(WatcherJson(*w, life->final.last_sequence()));
  }
  const v1::Session& f = life->final;
  Json j = {{"type", "session"},
            {"camera", life->camera},
            {"kind", life->rtp ? "rtp" : "rtsp_push"},
            {"name", f.name()},
            {"state", v1::Session::State_Name(f.state())},
            {"state_message", f.state_message()},
            {"created_s", life->created_s},
            {"ended_s", life->ended_s},
            {"frames", f.stats().frames()},
            {"fps_p50", Percentile(life->fps, 0.5)},
            {"lag_ms_p50", Percentile(life->lag_ms, 0.5)},
            {"lag_ms_p95", Percentile(life->lag_ms, 0.95)},
            {"lag_ms_p99", Percentile(life->lag_ms, 0.99)},
            {"camera_killed", life->camera_killed},
            {"camera_starts", life->camera_starts},
            {"server_restarts", life->epoch_at_end - life->epoch_at_create},
            {"rtp_packets_dropped", life->relay_dropped},
            {"kernel_udp_drops", life->kernel_udp_drops},
            {"relay_socket_drops", life->relay_socket_drops},
            {"whole", life->whole()},
            {"offline", life->offline},
            {"watchers", watchers}};
  char line[256];
  std::snprintf(line, sizeof(line), "camera %d %s %s frames %lld whole %d offline: %s",
                life->camera, f.name().c_str(), v1::Session::State_Name(f.state()).c_str(),
                static_cast<long long>(f.stats().frames()), life->whole(), life->offline.c_str());
  Event(line, j);
  std::lock_guard<std::mutex> lock(mu_);
  lives_.push_back(std::move(life));
}

// A client whose channel reconnects within a second of the server's return
// (gRPC's default backoff grows to two minutes).
std::unique_ptr<SlapseClient> FastReconnectClient(int port, double watch_timeout_s) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 200);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 200);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 1000);
  auto channel = grpc::CreateCustomChannel("127.0.0.1:" + std::to_string(port),
                                           grpc::InsecureChannelCredentials(), args);
  client::ClientOptions o;
  o.rpc_timeout_s = 10;
  o.watch_timeout_s = watch_timeout_s;
  return std::make_unique<SlapseClient>(
      std::shared_ptr<v1::SlapseService::StubInterface>(v1::SlapseService::NewStub(channel)), o);
}

int Soak::Run() {
  g_start = Clock::now();
  port_ = testing::FreeLoopbackTcpPort();
  rtsp_port_ = testing::FreeLoopbackTcpPort();
  client_ = FastReconnectClient(port_, 0);
  // A watch is cut after 300 s and resumed from its cursor (a "reconnect"),
  // so a stuck stream cannot hang the soak.
  watch_client_ = FastReconnectClient(port_, 300);
  rng_.seed(o_.seed);
  if (!o_.json_path.empty()) json_.open(o_.json_path);
  StartServer();
  if (!client_->ListSessions(1, "", v1::Session::STATE_UNSPECIFIED).ok()) {
    std::fprintf(stderr, "soak: the server did not start, see %s/serve.log\n", o_.work_dir.c_str());
    return 1;
  }
  Event("server up on 127.0.0.1:" + std::to_string(port_) + ", RTSP ingest port " +
            std::to_string(rtsp_port_) + ", data " + o_.work_dir + "/data",
        {{"type", "server_up"}, {"life", 0}});
  for (int i = 0; i < o_.cameras; ++i) {
    slots_.push_back(std::make_unique<CameraSlot>(this, i, i < o_.rtp_cameras));
  }
  for (auto& slot : slots_) {
    threads_.emplace_back([this, s = slot.get()] {
      s->Run();
      ++slots_done_;
    });
  }
  std::vector<double> next_fault_s = {o_.camera_kill_every_s, o_.watcher_drop_every_s,
                                      o_.server_kill_every_s, o_.loss_every_s};
  double next_rss_s = 0;
  while (NowS() < o_.duration_s) {
    if (NowS() >= next_rss_s) {
      SampleRss();
      next_rss_s += o_.sample_s;
    }
    InjectFaults(NowS(), &next_fault_s);
    SleepS(0.1);
  }
  stopping_ = true;
  Event("duration over: no new sessions, waiting for the last ones", {{"type", "drain"}});
  Drain();
  server_->Signal(SIGTERM);
  server_->Wait(std::chrono::seconds(30));
  return Summarise();
}

// Waits for the running sessions to end on their own; past --drain-s their
// cameras are killed (those sessions count as not whole).
void Soak::Drain() {
  const double deadline_s = o_.duration_s + o_.drain_s;
  double next_rss_s = NowS();
  while (slots_done_ < o_.cameras) {
    if (NowS() >= next_rss_s) {
      SampleRss();
      next_rss_s += o_.sample_s;
    }
    if (NowS() > deadline_s && !aborting_) {
      aborting_ = true;
      Event("drain time over: killing the remaining cameras", {{"type", "drain_timeout"}});
      for (auto& slot : slots_) slot->KillCamera();
    }
    if (NowS() > deadline_s + 60) give_up_ = true;  // watchers stop
    SleepS(0.1);
  }
  for (std::thread& t : threads_) t.join();
}

void Soak::PrintRss() const {
  std::printf("\nServer RSS (/proc/<pid>/status VmRSS; `life` counts server restarts):\n\n");
  std::printf("| t (s) | life | since start (s) | RSS (MiB) | live sessions |\n");
  std::printf("|---:|---:|---:|---:|---:|\n");
  const size_t step = std::max<size_t>(1, rss_.size() / 24);
  for (size_t i = 0; i < rss_.size(); ++i) {
    const bool life_end = i + 1 == rss_.size() || rss_[i + 1].life != rss_[i].life;
    if (i % step != 0 && !life_end) continue;
    const RssSample& r = rss_[i];
    std::printf("| %.0f | %llu | %.0f | %.1f | %d |\n", r.t_s,
                static_cast<unsigned long long>(r.life), r.since_start_s, r.rss_mib, r.sessions);
  }
  std::printf("\nAfter %.0f s of warm-up per server life:\n\n", o_.warmup_s);
  std::printf("| life | samples | first (MiB) | last (MiB) | max (MiB) | slope (MiB/h) |\n");
  std::printf("|---:|---:|---:|---:|---:|---:|\n");
  for (uint64_t life = 0; life < life_start_s_.size(); ++life) {
    std::vector<double> t, mib;
    for (const RssSample& r : rss_) {
      if (r.life == life && r.since_start_s >= o_.warmup_s && r.rss_mib > 0) {
        t.push_back(r.t_s / 3600.0);
        mib.push_back(r.rss_mib);
      }
    }
    if (t.empty()) {
      std::printf("| %llu | 0 | | | | (shorter than the warm-up) |\n",
                  static_cast<unsigned long long>(life));
      continue;
    }
    std::printf("| %llu | %zu | %.1f | %.1f | %.1f | %+.1f |\n",
                static_cast<unsigned long long>(life), t.size(), mib.front(), mib.back(),
                *std::max_element(mib.begin(), mib.end()), LeastSquaresSlope(t, mib));
  }
}

// "camera killed, 2 restarts, 31 packets dropped" or "-".
std::string FaultsOf(const Life& l) {
  std::string out;
  auto add = [&](const std::string& s) { out += (out.empty() ? "" : ", ") + s; };
  if (l.camera_killed) add("camera killed");
  if (l.camera_starts > 1) add("camera republished " + std::to_string(l.camera_starts - 1) + "x");
  if (l.epoch_at_end > l.epoch_at_create) {
    add("server restarted " + std::to_string(l.epoch_at_end - l.epoch_at_create) + "x");
  }
  if (l.relay_dropped > 0) add(std::to_string(l.relay_dropped) + " RTP packets dropped");
  return out.empty() ? "-" : out;
}

void Soak::PrintSessions() const {
  std::printf(
      "\nSessions (fps, lag: SessionStats sampled each second while RUNNING; events per "
      "watcher: delivered / expected, lost, repeated, drops + retries):\n\n");
  std::printf(
      "| camera | kind | session | end | frames | fps p50 | lag p50 / p95 / p99 (ms) | "
      "faults | events per watcher | lost | repeated | drops + retries | offline |\n");
  std::printf("|---:|---|---|---|---:|---:|---|---|---|---:|---:|---|---|\n");
  for (const auto& l : lives_) {
    std::string events, resumes;
    uint64_t lost = 0, repeated = 0;
    for (const auto& w : l->watchers) {
      const LedgerTally t = w->ledger.Against(l->final.last_sequence());
      events += (events.empty() ? "" : ", ") + std::to_string(t.delivered) + "/" +
                std::to_string(t.expected);
      resumes += (resumes.empty() ? "" : ", ") + std::to_string(w->drops) + "+" +
                 std::to_string(w->retries);
      lost += t.lost;
      repeated += t.repeated + t.unexpected;
    }
    const std::string& name = l->final.name();
    std::printf(
        "| %d | %s | %s | %s | %lld | %.1f | %.0f / %.0f / %.0f | %s | %s | %llu | %llu | "
        "%s | %s |\n",
        l->camera, l->rtp ? "RTP" : "RTSP", name.substr(name.size() - 6).c_str(),
        v1::Session::State_Name(l->final.state()).c_str(),
        static_cast<long long>(l->final.stats().frames()), Percentile(l->fps, 0.5),
        Percentile(l->lag_ms, 0.5), Percentile(l->lag_ms, 0.95), Percentile(l->lag_ms, 0.99),
        FaultsOf(*l).c_str(), events.c_str(), static_cast<unsigned long long>(lost),
        static_cast<unsigned long long>(repeated), resumes.c_str(), l->offline.c_str());
  }
}

int Soak::Summarise() {
  std::lock_guard<std::mutex> lock(mu_);
  PrintRss();
  PrintSessions();
  LedgerTally sum;
  int whole = 0, equal = 0, drops = 0, retries = 0, short_udp = 0, short_unexplained = 0;
  std::vector<double> lag_ms, fps;
  for (const auto& l : lives_) {
    whole += l->whole();
    const bool udp_drops = l->kernel_udp_drops + l->relay_socket_drops > 0;
    short_udp += l->short_stream() && udp_drops;
    short_unexplained += l->short_stream() && !udp_drops;
    equal += l->offline == "equal";
    lag_ms.insert(lag_ms.end(), l->lag_ms.begin(), l->lag_ms.end());
    fps.insert(fps.end(), l->fps.begin(), l->fps.end());
    for (const auto& w : l->watchers) {
      const LedgerTally t = w->ledger.Against(l->final.last_sequence());
      sum.expected += t.expected;
      sum.delivered += t.delivered;
      sum.lost += t.lost;
      sum.repeated += t.repeated;
      sum.unexpected += t.unexpected;
      drops += w->drops;
      retries += w->retries;
    }
  }
  uint64_t data_bytes = 0;
  std::error_code ec;
  for (const auto& f : std::filesystem::recursive_directory_iterator(o_.work_dir + "/data", ec)) {
    if (f.is_regular_file(ec)) data_bytes += f.file_size(ec);
  }
  const bool pass = sum.lost == 0 && sum.repeated == 0 && sum.unexpected == 0 && whole > 0 &&
                    equal == whole && short_unexplained == 0;
  std::printf(
      "\nsummary: %zu sessions, %d whole, %d of them equal to the offline run; fault-free but "
      "short %d (UDP socket drops) + %d (unexplained); events "
      "delivered %llu of %llu expected, %llu lost, %llu repeated, %llu unexpected; watcher drops "
      "%d, retries %d; faults: %d camera kills, %d watcher drops, %d server restarts, %d RTP "
      "loss bursts; fps p50 %.1f, lag p50 / p95 / p99 %.0f / %.0f / %.0f ms; data dir %.1f MiB; "
      "%s\n",
      lives_.size(), whole, equal, short_udp, short_unexplained,
      static_cast<unsigned long long>(sum.delivered), static_cast<unsigned long long>(sum.expected),
      static_cast<unsigned long long>(sum.lost), static_cast<unsigned long long>(sum.repeated),
      static_cast<unsigned long long>(sum.unexpected), drops, retries, faults_[0], faults_[1],
      faults_[2], faults_[3], Percentile(fps, 0.5), Percentile(lag_ms, 0.5),
      Percentile(lag_ms, 0.95), Percentile(lag_ms, 0.99), data_bytes / 1048576.0,
      pass ? "PASS" : "FAIL");
  if (json_.is_open()) {
    json_ << Json({{"type", "summary"},
                   {"sessions", lives_.size()},
                   {"whole", whole},
                   {"equal_offline", equal},
                   {"short_udp_drops", short_udp},
                   {"short_unexplained", short_unexplained},
                   {"events_expected", sum.expected},
                   {"events_delivered", sum.delivered},
                   {"events_lost", sum.lost},
                   {"events_repeated", sum.repeated},
                   {"events_unexpected", sum.unexpected},
                   {"data_dir_bytes", data_bytes},
                   {"pass", pass}})
                 .dump()
          << "\n";
  }
  return pass ? 0 : 1;
}

void AddFlags(CLI::App* app, SoakOptions* o) {
  auto add = [&](const char* name, auto* value, const char* help) {
    app->add_option(name, *value, help)->capture_default_str();
  };
  add("--cameras", &o->cameras, "camera slots (each runs sessions back to back)");
  add("--rtp-cameras", &o->rtp_cameras, "of them RTP through the lossy relay, the rest RTSP push");
  add("--watchers", &o->watchers, "watchers per session");
  add("--duration-s", &o->duration_s, "new sessions and faults until then");
  add("--drive-s", &o->drive_s, "simulated drive length");
  add("--loops", &o->loops, "times the drive is sent per session (ffmpeg -stream_loop)");
  add("--camera-kill-every-s", &o->camera_kill_every_s, "0: never");
  add("--camera-restart-s", &o->camera_restart_s, "a killed camera's pause");
  add("--watcher-drop-every-s", &o->watcher_drop_every_s, "0: never");
  add("--watcher-pause-s", &o->watcher_pause_s, "a dropped watcher's pause");
  add("--server-kill-every-s", &o->server_kill_every_s, "SIGKILL + restart; 0: never");
  add("--loss-every-s", &o->loss_every_s, "an RTP loss burst; 0: never");
  add("--loss-burst-s", &o->loss_burst_s, "a loss burst's length");
  add("--loss-rate", &o->loss_rate, "RTP packets dropped in a burst, share");
  add("--sample-s", &o->sample_s, "RSS sample period");
  add("--warmup-s", &o->warmup_s, "per server life, before the RSS slope counts");
  add("--drain-s", &o->drain_s, "after the duration, longest wait for the last sessions");
  add("--retention-ttl-s", &o->retention_ttl_s,
      "the server's: finished sessions deleted this long after their end (0: kept)");
  add("--seed", &o->seed, "drive and fault victims");
  add("--work-dir", &o->work_dir, "drive, data dir, serve.log (default: a temp dir)");
  add("--json", &o->json_path, "JSON lines: rss, fault, session, summary");
  add("--slapse", &o->slapse, "the slapse binary");
}

struct Reference {
  std::string tum;     // slapse run's trajectory_tum.txt
  int64_t frames = 0;  // the frames it read
  size_t poses = 0;
};

// The offline reference: the bytes a camera sends (the drive --loops times,
// as ffmpeg -stream_loop makes them), through `slapse run`.
StatusOr<Reference> MakeReference(const SoakOptions& o, const testing::TestDrive& drive) {
  const std::string cycle = o.work_dir + "/cycle.ts", offline = o.work_dir + "/offline";
  const std::string loop_cmd = "ffmpeg -nostdin -loglevel error -y -stream_loop " +
                               std::to_string(o.loops - 1) + " -i '" + drive.video_path +
                               "' -c copy '" + cycle + "'";
  const std::string run_cmd = "'" + o.slapse + "' run '" + cycle + "' --intrinsics '" + drive.dir +
                              "/intrinsics.json' --out '" + offline + "' --quiet > '" + o.work_dir +
                              "/offline.log' 2>&1";
  if (testing::RunCommand(loop_cmd) != 0 || testing::RunCommand(run_cmd) != 0) {
    return InternalError("the offline reference failed: " + loop_cmd + "; " + run_cmd);
  }
  Reference r;
  r.tum = testing::ReadFileBytes(offline + "/trajectory_tum.txt");
  std::istringstream lines(r.tum);
  std::string line;
  while (std::getline(lines, line)) r.poses += !line.empty() && line[0] != '#';
  // run's first line: "input <path> (<codec>, <w>x<h>, <n> frames)".
  const std::string log = testing::ReadFileBytes(o.work_dir + "/offline.log");
  const size_t frames_at = log.find(" frames)");
  const size_t comma = frames_at == std::string::npos ? frames_at : log.rfind(", ", frames_at);
  if (comma != std::string::npos) r.frames = std::atoll(log.c_str() + comma + 2);
  if (r.poses == 0 || r.frames <= 0) return InternalError("no offline reference in " + offline);
  return r;
}

}  // namespace
}  // namespace slapse::bench

int main(int argc, char** argv) {
  slapse::bench::SoakOptions o;
  CLI::App app("soak: live cameras and watchers against `slapse serve` with faults on a schedule");
  slapse::bench::AddFlags(&app, &o);
  CLI11_PARSE(app, argc, argv);
  if (o.cameras < 1 || o.rtp_cameras < 0 || o.rtp_cameras > o.cameras || o.loops < 1 ||
      o.watchers < 0 || o.drive_s <= 0) {
    std::fprintf(stderr,
                 "soak: need --cameras >= 1, 0 <= --rtp-cameras <= --cameras, --loops >= 1, "
                 "--watchers >= 0, --drive-s > 0\n");
    return 2;
  }
  signal(SIGPIPE, SIG_IGN);
  if (o.work_dir.empty()) o.work_dir = slapse::testing::MakeTempDir("soak");
  std::filesystem::create_directories(o.work_dir);
  auto drive = slapse::testing::SimulateTestDrive(
      "soak_drive", slapse::testing::SmallMpeg2DriveOptions(o.seed, o.drive_s));
  auto reference = drive.ok() ? slapse::bench::MakeReference(o, *drive)
                              : slapse::StatusOr<slapse::bench::Reference>(drive.status());
  if (!reference.ok()) {
    std::fprintf(stderr, "soak: %s\n", reference.status().ToString().c_str());
    return 1;
  }
  double load[3] = {0, 0, 0};
  getloadavg(load, 3);
  std::printf(
      "soak: %d cameras (%d RTP), %d watchers each, %.0f s; drive %.0f s x %d per session "
      "(320x240 MPEG-2, seed %llu), offline reference %lld frames, %zu poses; faults every: "
      "camera kill %.0f s, watcher drop %.0f s, server restart %.0f s, RTP loss %.0f s (%.0f s at "
      "%.0f%%); %ld CPUs, load average %.2f at start; work dir %s\n",
      o.cameras, o.rtp_cameras, o.watchers, o.duration_s, o.drive_s, o.loops,
      static_cast<unsigned long long>(o.seed), static_cast<long long>(reference->frames),
      reference->poses, o.camera_kill_every_s, o.watcher_drop_every_s, o.server_kill_every_s,
      o.loss_every_s, o.loss_burst_s, 100 * o.loss_rate, sysconf(_SC_NPROCESSORS_ONLN), load[0],
      o.work_dir.c_str());
  std::fflush(stdout);
  slapse::bench::Soak soak(o, *drive, reference->tum, reference->frames);
  const int rc = soak.Run();
  getloadavg(load, 3);
  std::printf("load average %.2f at the end\n", load[0]);
  return rc;
}
