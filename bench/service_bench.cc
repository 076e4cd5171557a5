// service_bench: how many live sessions one slapse server keeps up with, what
// each costs in memory, and how long a pose takes from frame to client.
//
//   build/bench/service_bench                      # 1, 2 and 3 sessions, 20 s drive
//   build/bench/service_bench --sessions 1,2,4 --duration 30
//   build/bench/service_bench --sessions 4 --ingest upload --loops 15   # 5 min each
//
// Each session count runs in a fresh process of its own (so its memory figures
// are its own): an in-process server (port 0, its store in a fresh data
// directory on disk, as `slapse serve`), N live sessions, each fed the
// same simulated drive (MPEG-2 IBBBP, 30 fps) at real time by its own
// `ffmpeg -re` (--loops times in a row), and a watcher per session on the real
// client library. --ingest push (default): RTSP push sessions, ffmpeg
// publishing to each ingest URL; --ingest upload: upload sessions, ffmpeg
// writing MPEG-TS to a pipe that the bench streams with UploadStream as it
// comes (a live camera's pace, not a file's).
// Reported per run:
//   - keeps up: the session's lag_ms (wall time since its first frame minus the
//     stream time processed) stayed below --max-lag-ms after the first second
//     and it processed every frame; fps is SessionStats.fps (30 = real time).
//   - RSS per session: (RSS of the process - RSS of the idle server) / N, at
//     the run's peak and steady (the mean over the last quarter of the run
//     after --warmup seconds); the same for the anonymous pages alone (heap,
//     arenas, stacks: RssAnon; the rest are shared libraries' pages, loaded
//     once). The process holds the server and the N watchers.
//   - RSS slope: least squares of the RSS samples (every 250 ms) after the
//     warm-up against time, MiB per hour: ~0 = flat.
//   - update latency: client receipt time of each PoseUpdate minus its
//     frame_received_time (when the server's reader delivered the anchor frame),
//     same clock. Frames queued in the socket before the reader are not in it
//     (lag_ms shows those).
//   - server CPU per stream second: the process's CPU time (server, ingest,
//     watchers; not the ffmpeg publishers, separate processes) over the stream
//     seconds all sessions processed, and the sessions the machine's CPUs
//     would keep at that cost (an upper bound: it ignores contention).
// Timing lives here, never in tests.
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern "C" {
#include <libavutil/log.h>
}

#include "api/convert.h"
#include "bench/rss.h"
#include "bench/stats.h"
#include "client/lib/client.h"
#include "core/common/intrinsics_io.h"
#include "lab/sim/simulate.h"
#include "server/server.h"

namespace {

namespace v1 = slapse::v1;
using google::protobuf::util::TimeUtil;
using slapse::Status;
using slapse::bench::Percentile;

// The wall clock as a Timestamp, to the nanosecond (as the server stamps).
google::protobuf::Timestamp Now() {
  return TimeUtil::NanosecondsToTimestamp(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                              std::chrono::system_clock::now().time_since_epoch())
                                              .count());
}

// How one run feeds and measures its sessions (the parent's flags).
struct RunConfig {
  int sessions = 1;
  std::string video, ingest = "push";
  int loops = 1;  // the drive fed this many times in a row
  double max_lag_ms = 1000, warmup_s = 5;
  int event_ring = 0;  // SessionManagerOptions::event_ring_capacity; 0 = its default
};

// `ffmpeg -re` sending `video` (loops times) to `out` in `format`, as a
// child; `out` "-" = its stdout, read through the returned FILE (else null).
pid_t StartFfmpeg(const RunConfig& c, const std::string& format, const std::string& out,
                  FILE** stdout_pipe) {
  int fds[2] = {-1, -1};
  if (stdout_pipe != nullptr && pipe(fds) != 0) return -1;
  const std::string loops = std::to_string(std::max(0, c.loops - 1));
  const pid_t pid = fork();
  if (pid == 0) {
    if (stdout_pipe != nullptr) dup2(fds[1], 1);
    std::vector<const char*> argv = {
        "ffmpeg", "-nostdin",      "-loglevel", "error", "-re", "-stream_loop", loops.c_str(),
        "-i",     c.video.c_str(), "-c",        "copy",  "-f",  format.c_str()};
    if (format == "rtsp") argv.insert(argv.end(), {"-rtsp_transport", "tcp"});
    argv.insert(argv.end(), {out.c_str(), nullptr});
    execvp("ffmpeg", const_cast<char* const*>(argv.data()));
    _exit(127);
  }
  if (stdout_pipe != nullptr) {
    close(fds[1]);
    *stdout_pipe = fdopen(fds[0], "rb");
  }
  return pid;
}

// Starts a publisher; the session's listener opens within milliseconds of
// creation, so a publisher that exits at once (refused) is started again.
pid_t PublishWithRetry(const RunConfig& c, const std::string& url) {
  for (int attempt = 0; attempt < 20; ++attempt) {
    const pid_t pid = StartFfmpeg(c, "rtsp", url, nullptr);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) == 0) return pid;  // running: connected
  }
  return -1;
}

// An upload session fed live: ffmpeg's MPEG-TS on a pipe, streamed as it comes.
Status UploadLive(slapse::client::SlapseClient* client, const std::string& name,
                  const RunConfig& c) {
  FILE* in = nullptr;
  const pid_t pid = StartFfmpeg(c, "mpegts", "-", &in);
  if (pid < 0 || in == nullptr) return slapse::InternalError("cannot start ffmpeg");
  auto done = client->Upload(name, [&](std::string* chunk) {
    chunk->resize(64 << 10);
    const size_t got = std::fread(chunk->data(), 1, chunk->size(), in);
    chunk->resize(got);
    return got > 0;
  });
  std::fclose(in);
  waitpid(pid, nullptr, 0);
  return done.status();
}

// The process's memory over a run, one sample every 250 ms.
struct MemorySample {
  double t_s;
  long rss_kb, anon_kb;
};

struct MemoryFigures {
  double peak_mib = 0, steady_mib = 0, steady_anon_mib = 0, slope_mib_per_h = 0;
};

// Peak; steady = the mean over the last quarter of the samples after the
// warm-up; slope = least squares of RSS against time after the warm-up.
MemoryFigures Summarize(const std::vector<MemorySample>& samples, double warmup_s) {
  MemoryFigures f;
  std::vector<MemorySample> late;
  for (const MemorySample& s : samples) {
    f.peak_mib = std::max(f.peak_mib, s.rss_kb / 1024.0);
    if (s.t_s >= warmup_s) late.push_back(s);
  }
  if (late.empty()) return f;
  const size_t from = late.size() - std::max<size_t>(1, late.size() / 4);
  for (size_t i = from; i < late.size(); ++i) {
    f.steady_mib += late[i].rss_kb / 1024.0 / (late.size() - from);
    f.steady_anon_mib += late[i].anon_kb / 1024.0 / (late.size() - from);
  }
  std::vector<double> t_s, rss_mib;
  for (const MemorySample& s : late) {
    t_s.push_back(s.t_s);
    rss_mib.push_back(s.rss_kb / 1024.0);
  }
  f.slope_mib_per_h = slapse::bench::LeastSquaresSlope(t_s, rss_mib) * 3600.0;
  return f;
}

struct SessionOutcome {
  std::string name;
  v1::Session final;
  double max_lag_ms = 0;
  std::vector<double> latency_ms, emit_latency_ms;
  Status watch_end;
};

// Creates the N sessions (RTSP push: `urls` gets each one's publish URL).
Status CreateSessions(slapse::client::SlapseClient* client, const RunConfig& c,
                      const slapse::Intrinsics& k, std::vector<SessionOutcome>* out,
                      std::vector<std::string>* urls) {
  for (int i = 0; i < c.sessions; ++i) {
    v1::Session req;
    if (c.ingest == "upload") {
      req.mutable_upload();
    } else {
      req.mutable_rtsp_push()->set_path("cam" + std::to_string(i));
      req.mutable_rtsp_push()->set_start_timeout_ms(30000);
    }
    *req.mutable_intrinsics() = slapse::api::IntrinsicsToProto(k);
    auto s = client->CreateSession(req);
    if (!s.ok()) return s.status();
    (*out)[i].name = s->name();
    // The publish URL: the session's credentials put in (shown at creation only).
    if (c.ingest != "upload") {
      urls->push_back(slapse::server::RtspPublishUrl(
          s->ingest_url(),
          {s->publish_credentials().username(), s->publish_credentials().password()}));
    }
  }
  return Status();
}

// This process's CPU time (user + system, all threads), seconds.
double ProcessCpuS() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// Samples every session's statistics and the process's memory until all end.
std::vector<MemorySample> SampleUntilEnd(slapse::client::SlapseClient* client,
                                         std::vector<SessionOutcome>* out) {
  std::vector<MemorySample> samples;
  const auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    samples.push_back({std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
                       slapse::bench::RssKb(), slapse::bench::RssAnonKb()});
    int active = 0;
    for (SessionOutcome& s : *out) {
      auto got = client->GetSession(s.name);
      if (!got.ok()) continue;
      s.final = *got;
      const bool live =
          got->state() == v1::Session::CREATED || got->state() == v1::Session::RUNNING;
      active += live;
      if (got->stats().stream_time_s() >= 1.0) {
        s.max_lag_ms = std::max(s.max_lag_ms, got->stats().lag_ms());
      }
    }
    if (active == 0) return samples;
  }
}

// Prints one "session ..." line per session and the "run ..." line.
void Report(const RunConfig& c, const std::vector<SessionOutcome>& out, long idle_rss_kb,
            long idle_anon_kb, const MemoryFigures& m, double server_cpu_s) {
  std::vector<double> all_lat, all_emit;
  int keeping_up = 0;
  for (const SessionOutcome& s : out) {
    const auto& st = s.final.stats();
    const bool kept_up = s.final.state() == v1::Session::FINISHED && s.max_lag_ms < c.max_lag_ms;
    keeping_up += kept_up;
    all_lat.insert(all_lat.end(), s.latency_ms.begin(), s.latency_ms.end());
    all_emit.insert(all_emit.end(), s.emit_latency_ms.begin(), s.emit_latency_ms.end());
    std::printf(
        "session %s %s frames %lld fps %.1f max_lag_ms %.0f final_lag_ms %.0f "
        "poses %zu latency_p50_ms %.1f latency_p95_ms %.1f kept_up %d\n",
        s.name.c_str(), v1::Session::State_Name(s.final.state()).c_str(),
        static_cast<long long>(st.frames()), st.fps(), s.max_lag_ms, st.lag_ms(),
        s.latency_ms.size(), Percentile(s.latency_ms, 0.5), Percentile(s.latency_ms, 0.95),
        kept_up);
  }
  const int n = c.sessions;
  const double idle_mib = idle_rss_kb / 1024.0;
  // Server CPU per second of live stream: this process's CPU time (server,
  // its ingest and the watchers; not the ffmpeg publishers, which are other
  // processes) over the stream time all sessions processed. The sessions one
  // server keeps at that cost: the CPUs over it.
  double stream_s = 0;
  for (const SessionOutcome& s : out) stream_s += s.final.stats().stream_time_s();
  const double cpu_per_stream_s = stream_s > 0 ? server_cpu_s / stream_s : 0;
  const double sessions_at_cost =
      cpu_per_stream_s > 0 ? sysconf(_SC_NPROCESSORS_ONLN) / cpu_per_stream_s : 0;
  std::printf(
      "run sessions %d kept_up %d idle_rss_mib %.1f peak_rss_mib %.1f steady_rss_mib %.1f "
      "rss_per_session_mib %.1f steady_per_session_mib %.1f anon_per_session_mib %.1f "
      "slope_mib_per_h %.1f latency_p50_ms %.1f latency_p95_ms %.1f latency_max_ms %.1f "
      "emit_to_client_p50_ms %.2f server_cpu_s %.1f stream_s %.1f cpu_per_stream_s %.3f "
      "sessions_at_cost %.1f\n",
      n, keeping_up, idle_mib, m.peak_mib, m.steady_mib, (m.peak_mib - idle_mib) / n,
      (m.steady_mib - idle_mib) / n, (m.steady_anon_mib - idle_anon_kb / 1024.0) / n,
      m.slope_mib_per_h, Percentile(all_lat, 0.5), Percentile(all_lat, 0.95),
      Percentile(all_lat, 1.0), Percentile(all_emit, 0.5), server_cpu_s, stream_s, cpu_per_stream_s,
      sessions_at_cost);
  std::fflush(stdout);
}

// One run: N sessions at once, fed live, watched, measured.
int RunChild(const RunConfig& c, const slapse::Intrinsics& k) {
  slapse::server::ServerOptions o;
  o.address = "127.0.0.1";
  o.port = 0;
  o.sessions.max_sessions = c.sessions;
  // A data directory on disk, as `slapse serve` has: an in-memory store would
  // hold every event and pose in the process and grow with the run.
  const std::filesystem::path data_dir =
      std::filesystem::temp_directory_path() / ("slapse_service_bench_" + std::to_string(getpid()));
  std::filesystem::remove_all(data_dir);
  o.sessions.data_dir = data_dir.string();
  if (c.event_ring > 0) o.sessions.event_ring_capacity = static_cast<size_t>(c.event_ring);
  auto server = slapse::server::SlapseServer::Start(o);
  if (!server.ok()) {
    std::fprintf(stderr, "service_bench: %s\n", server.status().ToString().c_str());
    return 1;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const long idle_rss_kb = slapse::bench::RssKb(), idle_anon_kb = slapse::bench::RssAnonKb();
  slapse::client::ClientOptions co;
  co.upload_timeout_s = 0;  // a live upload lasts as long as its camera
  auto client =
      slapse::client::SlapseClient::Connect("127.0.0.1:" + std::to_string((*server)->port()), co);

  std::vector<SessionOutcome> out(c.sessions);
  std::vector<std::string> urls;
  const double cpu0_s = ProcessCpuS();
  if (Status s = CreateSessions(client.get(), c, k, &out, &urls); !s.ok()) {
    std::fprintf(stderr, "service_bench: create: %s\n", s.ToString().c_str());
    return 1;
  }
  std::vector<std::thread> threads;
  std::mutex mu;
  for (int i = 0; i < c.sessions; ++i) {
    threads.emplace_back([&, i] {
      std::vector<double> lat, emit_lat;
      Status st = client->Watch(out[i].name, 0, [&](const v1::SessionEvent& e) {
        if (!e.has_pose()) return true;
        const auto now = Now();
        lat.push_back(TimeUtil::DurationToMicroseconds(now - e.pose().frame_received_time()) / 1e3);
        emit_lat.push_back(TimeUtil::DurationToMicroseconds(now - e.pose().emit_time()) / 1e3);
        return true;
      });
      std::lock_guard<std::mutex> lock(mu);
      out[i].latency_ms = std::move(lat);
      out[i].emit_latency_ms = std::move(emit_lat);
      out[i].watch_end = st;
    });
  }
  std::vector<pid_t> publishers;
  for (int i = 0; i < c.sessions; ++i) {
    if (c.ingest == "upload") {
      threads.emplace_back([&, i] {
        if (Status s = UploadLive(client.get(), out[i].name, c); !s.ok()) {
          std::fprintf(stderr, "service_bench: upload: %s\n", s.ToString().c_str());
        }
      });
      continue;
    }
    const pid_t pid = PublishWithRetry(c, urls[i]);
    if (pid < 0) std::fprintf(stderr, "service_bench: no publisher for %s\n", urls[i].c_str());
    publishers.push_back(pid);
  }

  const std::vector<MemorySample> samples = SampleUntilEnd(client.get(), &out);
  const double server_cpu_s = ProcessCpuS() - cpu0_s;
  for (std::thread& t : threads) t.join();
  for (pid_t pid : publishers) {
    if (pid > 0) waitpid(pid, nullptr, 0);
  }
  (*server)->Shutdown();
  std::filesystem::remove_all(data_dir);
  Report(c, out, idle_rss_kb, idle_anon_kb, Summarize(samples, c.warmup_s), server_cpu_s);
  return 0;
}

// The token after `key` in a line of space-separated tokens.
std::string Field(const std::string& line, const std::string& key) {
  std::istringstream in(line);
  std::string token;
  while (in >> token) {
    if (token == key && in >> token) return token;
  }
  return "?";
}

// A fresh process per session count (this binary again, with --child N);
// prints one table row each.
int RunParent(const std::string& sessions, const RunConfig& c, const slapse::Intrinsics& k) {
  double load[3] = {0, 0, 0};
  getloadavg(load, 3);
  std::printf(
      "input %s (%dx%d) x %d, fed with ffmpeg -re (%s); %ld CPUs, load average %.2f at start; "
      "keeps up = FINISHED with lag_ms < %.0f after 1 s; steady and slope after %.0f s\n\n",
      c.video.c_str(), k.width_px, k.height_px, c.loops,
      c.ingest == "upload" ? "upload sessions, MPEG-TS on a pipe" : "RTSP push over TCP",
      sysconf(_SC_NPROCESSORS_ONLN), load[0], c.max_lag_ms, c.warmup_s);
  std::printf(
      "| sessions | keep up | fps per session | max lag_ms per session | RSS idle | "
      "RSS per session: peak / steady / anon | RSS slope | update latency p50 / p95 / max | "
      "server CPU per stream second | sessions at that cost |\n");
  std::printf("|---:|---:|---|---|---:|---:|---:|---:|---:|---:|\n");
  char self[4096];
  const ssize_t len = readlink("/proc/self/exe", self, sizeof(self) - 1);
  if (len <= 0) return 1;
  self[len] = '\0';
  std::stringstream list(sessions);
  std::string item;
  while (std::getline(list, item, ',')) {
    const int n = std::atoi(item.c_str());
    if (n < 1) continue;
    const std::string cmd = std::string("'") + self + "' --child " + std::to_string(n) +
                            " --input '" + c.video + "' --max-lag-ms " +
                            std::to_string(c.max_lag_ms) + " --ingest " + c.ingest + " --loops " +
                            std::to_string(c.loops) + " --warmup " + std::to_string(c.warmup_s) +
                            " --event-ring " + std::to_string(c.event_ring);
    FILE* p = popen(cmd.c_str(), "r");
    if (p == nullptr) return 1;
    std::string fps, lags, run;
    char buf[1024];
    while (std::fgets(buf, sizeof(buf), p) != nullptr) {
      const std::string line(buf);
      std::fprintf(stderr, "  %s", buf);  // the raw figures, per session
      if (line.rfind("session ", 0) == 0) {
        fps += (fps.empty() ? "" : ", ") + Field(line, "fps");
        lags += (lags.empty() ? "" : ", ") + Field(line, "max_lag_ms");
      } else if (line.rfind("run ", 0) == 0) {
        run = line;
      }
    }
    if (pclose(p) != 0 || run.empty()) {
      std::printf("| %d | run failed | | | | | | | | |\n", n);
      continue;
    }
    std::printf(
        "| %d | %s of %d | %s | %s | %s MiB | %s / %s / %s MiB | %s MiB/h | %s / %s / %s ms | %s s "
        "| %s |\n",
        n, Field(run, "kept_up").c_str(), n, fps.c_str(), lags.c_str(),
        Field(run, "idle_rss_mib").c_str(), Field(run, "rss_per_session_mib").c_str(),
        Field(run, "steady_per_session_mib").c_str(), Field(run, "anon_per_session_mib").c_str(),
        Field(run, "slope_mib_per_h").c_str(), Field(run, "latency_p50_ms").c_str(),
        Field(run, "latency_p95_ms").c_str(), Field(run, "latency_max_ms").c_str(),
        Field(run, "cpu_per_stream_s").c_str(), Field(run, "sessions_at_cost").c_str());
    std::fflush(stdout);
  }
  return 0;
}

// The drive to feed: --input's, else one simulated once per (seed, duration,
// size) and reused from the temp dir. Empty on failure (said on stderr).
std::string DriveVideo(uint64_t seed, double duration_s, int width, int height) {
  char tag[128];
  std::snprintf(tag, sizeof(tag), "slapse_service_bench_s%llu_%gs_%dx%d",
                static_cast<unsigned long long>(seed), duration_s, width, height);
  const std::string dir = (std::filesystem::temp_directory_path() / tag).string();
  const std::string video = dir + "/drive.ts";
  if (std::filesystem::exists(video) && std::filesystem::exists(dir + "/intrinsics.json")) {
    return video;
  }
  slapse::SimulateOptions opt;
  opt.seed = seed;
  opt.duration_s = duration_s;
  opt.width_px = width;
  opt.height_px = height;
  opt.output_dir = dir;
  slapse::SimulateReport rep;
  if (slapse::Status s = slapse::SimulateDrive(opt, &rep); !s.ok()) {
    std::fprintf(stderr, "service_bench: %s\n", s.ToString().c_str());
    return "";
  }
  return rep.video_path;
}

}  // namespace

int main(int argc, char** argv) {
  av_log_set_level(AV_LOG_ERROR);
  std::string sessions = "1,2,3";
  RunConfig c;
  double duration_s = 20;
  int width = 640, height = 480, child = 0;
  uint64_t seed = 1;
  for (int i = 1; i < argc; ++i) {
    auto next = [&] { return i + 1 < argc ? argv[++i] : nullptr; };
    const char* a = argv[i];
    const char* v = nullptr;
    if (!std::strcmp(a, "--sessions") && (v = next())) {
      sessions = v;
    } else if (!std::strcmp(a, "--duration") && (v = next())) {
      duration_s = std::atof(v);
    } else if (!std::strcmp(a, "--size") && (v = next())) {
      std::sscanf(v, "%dx%d", &width, &height);
    } else if (!std::strcmp(a, "--seed") && (v = next())) {
      seed = std::strtoull(v, nullptr, 10);
    } else if (!std::strcmp(a, "--input") && (v = next())) {
      c.video = v;
    } else if (!std::strcmp(a, "--max-lag-ms") && (v = next())) {
      c.max_lag_ms = std::atof(v);
    } else if (!std::strcmp(a, "--ingest") && (v = next()) &&
               (!std::strcmp(v, "push") || !std::strcmp(v, "upload"))) {
      c.ingest = v;
    } else if (!std::strcmp(a, "--loops") && (v = next())) {
      c.loops = std::max(1, std::atoi(v));
    } else if (!std::strcmp(a, "--warmup") && (v = next())) {
      c.warmup_s = std::atof(v);
    } else if (!std::strcmp(a, "--event-ring") && (v = next())) {
      c.event_ring = std::atoi(v);
    } else if (!std::strcmp(a, "--child") && (v = next())) {  // internal
      child = std::atoi(v);
    } else {
      std::fprintf(stderr,
                   "usage: service_bench [--sessions 1,2,3] [--duration S] [--size WxH] "
                   "[--seed N] [--input DRIVE.ts (intrinsics.json beside)] [--max-lag-ms MS] "
                   "[--ingest push|upload] [--loops N] [--warmup S] [--event-ring N]\n");
      return 2;
    }
  }
  if (c.video.empty()) c.video = DriveVideo(seed, duration_s, width, height);
  if (c.video.empty()) return 1;
  const std::string k_path =
      (std::filesystem::path(c.video).parent_path() / "intrinsics.json").string();
  auto k = slapse::ReadIntrinsicsJson(k_path);
  if (!k.ok()) {
    std::fprintf(stderr, "service_bench: %s\n", k.status().ToString().c_str());
    return 1;
  }
  if (child > 0) {
    c.sessions = child;
    return RunChild(c, *k);
  }
  return RunParent(sessions, c, *k);
}
