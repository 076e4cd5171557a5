// service_bench: how many live sessions one slapse server keeps up with, what
// each costs in memory, and how long a pose takes from frame to client.
//
//   build/bench/service_bench                      # 1, 2 and 3 sessions, 20 s drive
//   build/bench/service_bench --sessions 1,2,4 --duration 30
//
// Each session count runs in a fresh process of its own (so its memory figures
// are its own): an in-process server (port 0), N RTSP push sessions, N
// `ffmpeg -re` publishers sending the same simulated drive (MPEG-2 IBBBP,
// 30 fps) at real time, and a watcher per session on the real client library.
// Reported per run:
//   - keeps up: the session's lag_ms (wall time since its first frame minus the
//     stream time processed) stayed below --max-lag-ms after the first second
//     and it processed every frame; fps is SessionStats.fps (30 = real time).
//   - RSS per session: (peak RSS of the process during the run - RSS of the
//     idle server) / N. The process holds the server and the N watchers.
//   - update latency: client receipt time of each PoseUpdate minus its
//     frame_received_time (when the server's reader delivered the anchor frame),
//     same clock. Frames queued in the socket before the reader are not in it
//     (lag_ms shows those).
// Timing lives here, never in tests.
#include <signal.h>
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

// An `ffmpeg -re` publisher of `video` to `url` (RTSP over TCP), as a child.
pid_t StartPublisher(const std::string& video, const std::string& url) {
  const pid_t pid = fork();
  if (pid == 0) {
    execlp("ffmpeg", "ffmpeg", "-nostdin", "-loglevel", "error", "-re", "-i", video.c_str(), "-c",
           "copy", "-f", "rtsp", "-rtsp_transport", "tcp", url.c_str(), nullptr);
    _exit(127);
  }
  return pid;
}

// Starts a publisher; the session's listener opens within milliseconds of
// creation, so a publisher that exits at once (refused) is started again.
pid_t PublishWithRetry(const std::string& video, const std::string& url) {
  for (int attempt = 0; attempt < 20; ++attempt) {
    const pid_t pid = StartPublisher(video, url);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) == 0) return pid;  // running: connected
  }
  return -1;
}

struct SessionOutcome {
  std::string name;
  v1::Session final;
  double max_lag_ms = 0;
  std::vector<double> latency_ms, emit_latency_ms;
  Status watch_end;
};

// One run: N sessions at once. Prints one "session ..." line per session and a
// "run ..." line, machine-readable, for the parent.
int RunChild(int n, const std::string& video, const slapse::Intrinsics& k, double max_lag_ms) {
  slapse::server::ServerOptions o;
  o.address = "127.0.0.1";
  o.port = 0;
  o.sessions.max_sessions = n;
  auto server = slapse::server::SlapseServer::Start(o);
  if (!server.ok()) {
    std::fprintf(stderr, "service_bench: %s\n", server.status().ToString().c_str());
    return 1;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const long idle_rss_kb = slapse::bench::RssKb();
  auto client =
      slapse::client::SlapseClient::Connect("127.0.0.1:" + std::to_string((*server)->port()));

  std::vector<SessionOutcome> out(n);
  std::vector<std::string> urls(n);
  for (int i = 0; i < n; ++i) {
    v1::Session req;
    req.mutable_rtsp_push()->set_path("cam" + std::to_string(i));
    req.mutable_rtsp_push()->set_start_timeout_ms(30000);
    *req.mutable_intrinsics() = slapse::api::IntrinsicsToProto(k);
    auto s = client->CreateSession(req);
    if (!s.ok()) {
      std::fprintf(stderr, "service_bench: create: %s\n", s.status().ToString().c_str());
      return 1;
    }
    out[i].name = s->name();
    // The publish URL: the session's credentials put in (shown at creation only).
    urls[i] = slapse::server::RtspPublishUrl(
        s->ingest_url(),
        {s->publish_credentials().username(), s->publish_credentials().password()});
  }
  std::vector<std::thread> watchers;
  std::mutex mu;
  for (int i = 0; i < n; ++i) {
    watchers.emplace_back([&, i] {
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
  for (int i = 0; i < n; ++i) {
    const pid_t pid = PublishWithRetry(video, urls[i]);
    if (pid < 0) std::fprintf(stderr, "service_bench: no publisher for %s\n", urls[i].c_str());
    publishers.push_back(pid);
  }

  // Sample every session's statistics and the process's RSS until all end.
  long peak_rss_kb = idle_rss_kb;
  for (;;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    peak_rss_kb = std::max(peak_rss_kb, slapse::bench::RssKb());
    int active = 0;
    for (SessionOutcome& s : out) {
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
    if (active == 0) break;
  }
  for (std::thread& t : watchers) t.join();
  for (pid_t pid : publishers) {
    if (pid > 0) waitpid(pid, nullptr, 0);
  }
  (*server)->Shutdown();

  std::vector<double> all_lat, all_emit;
  int keeping_up = 0;
  for (const SessionOutcome& s : out) {
    const auto& st = s.final.stats();
    const bool kept_up = s.final.state() == v1::Session::FINISHED && s.max_lag_ms < max_lag_ms;
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
  std::printf(
      "run sessions %d kept_up %d idle_rss_mib %.1f peak_rss_mib %.1f "
      "rss_per_session_mib %.1f latency_p50_ms %.1f latency_p95_ms %.1f "
      "latency_max_ms %.1f emit_to_client_p50_ms %.2f\n",
      n, keeping_up, idle_rss_kb / 1024.0, peak_rss_kb / 1024.0,
      (peak_rss_kb - idle_rss_kb) / 1024.0 / n, Percentile(all_lat, 0.5), Percentile(all_lat, 0.95),
      Percentile(all_lat, 1.0), Percentile(all_emit, 0.5));
  std::fflush(stdout);
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

}  // namespace

int main(int argc, char** argv) {
  av_log_set_level(AV_LOG_ERROR);
  std::string sessions = "1,2,3", video;
  double duration_s = 20, max_lag_ms = 1000;
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
      video = v;
    } else if (!std::strcmp(a, "--max-lag-ms") && (v = next())) {
      max_lag_ms = std::atof(v);
    } else if (!std::strcmp(a, "--child") && (v = next())) {  // internal
      child = std::atoi(v);
    } else {
      std::fprintf(stderr,
                   "usage: service_bench [--sessions 1,2,3] [--duration S] [--size WxH] "
                   "[--seed N] [--input DRIVE.ts (intrinsics.json beside)] [--max-lag-ms MS]\n");
      return 2;
    }
  }
  if (video.empty()) {
    // The drive is made once per (seed, duration, size) and reused.
    char tag[128];
    std::snprintf(tag, sizeof(tag), "slapse_service_bench_s%llu_%gs_%dx%d",
                  static_cast<unsigned long long>(seed), duration_s, width, height);
    const std::string dir = (std::filesystem::temp_directory_path() / tag).string();
    video = dir + "/drive.ts";
    if (!std::filesystem::exists(video) || !std::filesystem::exists(dir + "/intrinsics.json")) {
      slapse::SimulateOptions opt;
      opt.seed = seed;
      opt.duration_s = duration_s;
      opt.width_px = width;
      opt.height_px = height;
      opt.output_dir = dir;
      slapse::SimulateReport rep;
      if (slapse::Status s = slapse::SimulateDrive(opt, &rep); !s.ok()) {
        std::fprintf(stderr, "service_bench: %s\n", s.ToString().c_str());
        return 1;
      }
      video = rep.video_path;
    }
  }
  const std::string k_path =
      (std::filesystem::path(video).parent_path() / "intrinsics.json").string();
  auto k = slapse::ReadIntrinsicsJson(k_path);
  if (!k.ok()) {
    std::fprintf(stderr, "service_bench: %s\n", k.status().ToString().c_str());
    return 1;
  }
  if (child > 0) return RunChild(child, video, *k, max_lag_ms);

  double load[3] = {0, 0, 0};
  getloadavg(load, 3);
  std::printf(
      "input %s (%dx%d), published with ffmpeg -re over RTSP (TCP); %ld CPUs, load "
      "average %.2f at start; keeps up = FINISHED with lag_ms < %.0f after 1 s\n\n",
      video.c_str(), k->width_px, k->height_px, sysconf(_SC_NPROCESSORS_ONLN), load[0], max_lag_ms);
  std::printf(
      "| sessions | keep up | fps per session | max lag_ms per session | RSS idle | "
      "RSS per session | update latency p50 / p95 / max |\n");
  std::printf("|---:|---:|---|---|---:|---:|---:|\n");
  std::stringstream list(sessions);
  std::string item;
  while (std::getline(list, item, ',')) {
    const int n = std::atoi(item.c_str());
    if (n < 1) continue;
    // A fresh process per run: this binary again, with --child N.
    char self[4096];
    const ssize_t len = readlink("/proc/self/exe", self, sizeof(self) - 1);
    if (len <= 0) return 1;
    self[len] = '\0';
    const std::string cmd = std::string("'") + self + "' --child " + std::to_string(n) +
                            " --input '" + video + "' --max-lag-ms " + std::to_string(max_lag_ms);
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
      std::printf("| %d | run failed | | | | | |\n", n);
      continue;
    }
    std::printf("| %d | %s of %d | %s | %s | %s MiB | %s MiB | %s / %s / %s ms |\n", n,
                Field(run, "kept_up").c_str(), n, fps.c_str(), lags.c_str(),
                Field(run, "idle_rss_mib").c_str(), Field(run, "rss_per_session_mib").c_str(),
                Field(run, "latency_p50_ms").c_str(), Field(run, "latency_p95_ms").c_str(),
                Field(run, "latency_max_ms").c_str());
    std::fflush(stdout);
  }
  return 0;
}
