// store_bench: a weeks-long session's cost in the server's store
// (server/store.h): the write cost per pipeline step, the restart recovery
// time, and a paged export's time and the server's memory.
//
//   build/bench/store_bench                          # 24 h at 30 poses/s in /tmp
//   build/bench/store_bench --hours 1 --data-dir /tmp/sb
//
// Phase 1 writes a synthetic pose feed (no video: the pipeline's cost is
// slapse_bench's business) through the same path a running session uses: per
// step one PoseUpdate event, one trajectory point, the session row and, every
// 10th step, a plane event and plane row, committed in one transaction by
// Session::CommitStep from EventLog::AppendBatch. Phase 2 starts a real
// server on that data directory (the restart: the store is opened and its
// sessions restored) and exports the trajectory over gRPC in pages of
// 20 000 points, dropping each page (so the client's memory stays small and
// the process's RSS is the server's plus a page).
// Timing lives here, never in tests.
#include <google/protobuf/util/time_util.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench/rss.h"
#include "client/lib/client.h"
#include "server/server.h"
#include "server/session.h"
#include "server/store.h"

namespace {

using Clock = std::chrono::steady_clock;
using namespace slapse;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

// Resident set size of this process, MiB (bench/rss.h; 0 if unreadable, as before).
double RssMiB() { return std::max(0L, slapse::bench::RssKb()) / 1024.0; }

double DirMiB(const std::string& dir) {
  uintmax_t bytes = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.is_regular_file()) bytes += e.file_size();
  }
  return static_cast<double>(bytes) / (1 << 20);
}

int Write(const std::string& dir, double hours, double fps) {
  auto opened = server::Store::Open(dir);
  if (!opened.ok()) return std::fprintf(stderr, "%s\n", opened.status().ToString().c_str()), 1;
  std::shared_ptr<server::Store> store = std::move(*opened);
  v1::Session row;
  row.set_name("sessions/benchbenchbenchbenchbench24");
  row.mutable_rtsp_pull()->set_url("rtsp://camera.invalid/stream");
  row.set_state(v1::Session::RUNNING);
  auto ordinal = store->AddSession(row);
  if (!ordinal.ok()) return std::fprintf(stderr, "%s\n", ordinal.status().ToString().c_str()), 1;
  server::Session session(row.name(), 4096, server::UploadQueueOptions{}, store, *ordinal);
  session.proto = row;
  const int64_t steps = static_cast<int64_t>(hours * 3600 * fps);
  const auto start = Clock::now();
  for (int64_t i = 0; i < steps; ++i) {
    const double t_s = static_cast<double>(i) / fps;
    server::StoreStep step;
    v1::Trajectory::Point p;
    p.set_anchor_index(i);
    p.set_timestamp_s(t_s);
    v1::Pose* pose = p.mutable_world_from_cam();
    pose->set_tx(10.0 * t_s);
    pose->set_ty(0.01 * t_s);
    pose->set_qw(1.0);
    step.points.push_back(p);
    std::vector<v1::SessionEvent> events(1);
    v1::PoseUpdate* pu = events[0].mutable_pose();
    pu->set_anchor_index(i);
    pu->set_timestamp_s(t_s);
    *pu->mutable_world_from_cam() = *pose;
    pu->set_tracking(true);
    if (i % 10 == 0) {
      v1::PlaneMap::Plane plane;
      plane.set_track_id(static_cast<int>(i / 10 % 64));
      plane.set_distance(1.5);
      plane.set_last_seen_s(t_s);
      step.planes.push_back(plane);
      events.emplace_back().mutable_plane()->set_track_id(plane.track_id());
    }
    session.proto.mutable_stats()->set_frames(i + 1);
    session.proto.mutable_stats()->set_anchor_pairs(i);
    session.proto.mutable_stats()->set_stream_time_s(t_s);
    v1::Session snapshot = session.proto;
    session.events->AppendBatch(std::move(events), [&](const std::vector<v1::SessionEvent>& b) {
      snapshot.set_last_sequence(b.back().sequence());
      step.session = &snapshot;
      session.CommitStep(step, b);
    });
    if (i > 0 && i % (steps / 10 > 0 ? steps / 10 : 1) == 0) {
      std::printf("  %5.1f%%  %.1f s  %.1f us/step  RSS %.0f MiB\n", 100.0 * i / steps,
                  Seconds(start), 1e6 * Seconds(start) / i, RssMiB());
      std::fflush(stdout);
    }
  }
  session.Transition(v1::Session::FINISHED, Status::Ok(), "bench feed ended");
  const double write_s = Seconds(start);
  std::printf(
      "write: %lld steps (%.1f h at %.0f poses/s) in %.1f s = %.1f us/step; "
      "data dir %.0f MiB; RSS %.0f MiB\n",
      static_cast<long long>(steps), hours, fps, write_s, 1e6 * write_s / steps, DirMiB(dir),
      RssMiB());
  return 0;
}

int Export(const std::string& dir) {
  const double rss_before = RssMiB();
  server::ServerOptions o;
  o.port = 0;
  o.sessions.data_dir = dir;
  const auto start = Clock::now();
  auto server = server::SlapseServer::Start(o);
  if (!server.ok()) return std::fprintf(stderr, "%s\n", server.status().ToString().c_str()), 1;
  const double restart_s = Seconds(start);
  std::printf("restart: store opened and sessions restored in %.3f s; RSS %.0f MiB (%.0f before)\n",
              restart_s, RssMiB(), rss_before);
  client::ClientOptions co;
  co.rpc_timeout_s = 120;
  auto c = client::SlapseClient::Connect("127.0.0.1:" + std::to_string((*server)->port()), co);
  auto list = c->ListSessions(1, "", v1::Session::STATE_UNSPECIFIED);
  if (!list.ok() || list->sessions_size() != 1) return std::fprintf(stderr, "no session\n"), 1;
  v1::GetTrajectoryRequest r;
  r.set_name(list->sessions(0).name());
  // One unpaged answer: refused beyond 40 000 points (not the 4 MB cap).
  auto unpaged = c->GetTrajectoryPage(r);
  std::printf("unpaged GetTrajectory: %s\n",
              unpaged.ok() ? "OK" : unpaged.status().ToString().c_str());
  r.set_page_size(20000);
  int64_t points = 0, pages = 0;
  double peak_rss = RssMiB();
  const auto export_start = Clock::now();
  do {
    auto page = c->GetTrajectoryPage(r);
    if (!page.ok()) return std::fprintf(stderr, "%s\n", page.status().ToString().c_str()), 1;
    points += page->points_size();
    ++pages;
    r.set_page_token(page->next_page_token());
    peak_rss = std::max(peak_rss, RssMiB());
  } while (!r.page_token().empty());
  const double export_s = Seconds(export_start);
  std::printf("export: %lld points in %lld pages in %.1f s (%.0f points/s); peak RSS %.0f MiB\n",
              static_cast<long long>(points), static_cast<long long>(pages), export_s,
              points / export_s, peak_rss);
  (*server)->Shutdown();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string dir = "/tmp/slapse_store_bench";
  double hours = 24, fps = 30;
  bool keep = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--data-dir" && i + 1 < argc) {
      dir = argv[++i];
    } else if (a == "--hours" && i + 1 < argc) {
      hours = std::atof(argv[++i]);
    } else if (a == "--fps" && i + 1 < argc) {
      fps = std::atof(argv[++i]);
    } else if (a == "--export-only") {
      keep = true;
    } else {
      std::fprintf(stderr,
                   "usage: store_bench [--data-dir DIR] [--hours H] [--fps F] [--export-only]\n");
      return 2;
    }
  }
  if (!keep) {
    std::filesystem::remove_all(dir);
    if (int rc = Write(dir, hours, fps); rc != 0) return rc;
  }
  return Export(dir);
}
