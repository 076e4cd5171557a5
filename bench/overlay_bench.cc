// overlay_bench: what the dashboard's frame overlays cost (server/frame_overlays.h).
//
//   build/bench/overlay_bench                       # simulates 10 s at 640x480 first
//   build/bench/overlay_bench --size 1280x720       # simulates at that size
//   build/bench/overlay_bench --input FILE
//
// Prints, in CPU time of the calling thread (steadier than wall time under a
// loaded machine):
//  - the reader per frame without and with keep_luma (the luma copy every
//    server session now pays);
//  - per anchor while someone watches: the runner's part (SetAnchor: the luma
//    moved, the vectors copied; SetPlanes: the step's planes copied);
//  - per anchor and picture, on the HTTP thread: drawing + scaling to 640 px +
//    PNG encoding (GET /api/overlay; at most once per anchor and kind), and
//    the PNG's size.
// Timing lives here, never in tests.
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "core/mv/mv_reader.h"
#include "core/pipeline/front_end.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/simulate.h"
#include "server/frame_overlays.h"

namespace {

double ThreadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// The reader's CPU ms per frame over `path`, each frame dropped after it is
// read (as the server's runner does), best of `repeat` passes.
double ReadMs(const std::string& path, bool keep_luma, int repeat) {
  double best = 1e30;
  for (int r = 0; r < repeat; ++r) {
    slapse::MvReaderOptions o;
    o.keep_luma = keep_luma;
    auto reader = slapse::MvReader::Open(path, o);
    if (!reader.ok()) return 0;
    slapse::FrameRecord f;
    long n = 0;
    const double t0 = ThreadCpuMs();
    while ((*reader)->Next(&f).ok()) ++n;
    best = std::min(best, (ThreadCpuMs() - t0) / std::max(1L, n));
  }
  return best;
}

// All frames of `path` with their luma.
std::vector<slapse::FrameRecord> ReadAll(const std::string& path) {
  slapse::MvReaderOptions o;
  o.keep_luma = true;
  auto reader = slapse::MvReader::Open(path, o);
  std::vector<slapse::FrameRecord> frames;
  if (!reader.ok()) return frames;
  slapse::FrameRecord f;
  while ((*reader)->Next(&f).ok()) frames.push_back(std::move(f));
  return frames;
}

}  // namespace

int main(int argc, char** argv) {
  std::string input;
  int width = 640, height = 480;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (std::strcmp(argv[i], "--input") == 0) input = argv[i + 1];
    if (std::strcmp(argv[i], "--size") == 0 &&
        std::sscanf(argv[i + 1], "%dx%d", &width, &height) != 2) {
      std::fprintf(stderr, "overlay_bench: --size WxH\n");
      return 2;
    }
  }
  if (input.empty()) {
    slapse::SimulateOptions opt;
    opt.width_px = width;
    opt.height_px = height;
    opt.output_dir =
        (std::filesystem::temp_directory_path() /
         ("slapse_overlay_bench_" + std::to_string(width) + "x" + std::to_string(height)))
            .string();
    slapse::SimulateReport rep;
    if (slapse::Status s = slapse::SimulateDrive(opt, &rep); !s.ok()) {
      std::fprintf(stderr, "overlay_bench: %s\n", s.ToString().c_str());
      return 1;
    }
    input = rep.video_path;
  }
  auto gt = slapse::LoadGroundTruth(std::filesystem::path(input).parent_path().string());
  if (!gt.ok()) {
    std::fprintf(stderr, "overlay_bench: needs a simulated drive's directory (intrinsics)\n");
    return 1;
  }
  // Alternating, so that a change in the machine's load hits both alike.
  double read_ms = 1e30, read_luma_ms = 1e30;
  for (int i = 0; i < 3; ++i) {
    read_ms = std::min(read_ms, ReadMs(input, false, 1));
    read_luma_ms = std::min(read_luma_ms, ReadMs(input, true, 1));
  }
  std::vector<slapse::FrameRecord> frames = ReadAll(input);
  if (frames.empty()) return 1;
  const int w = gt->intrinsics.width_px, h = gt->intrinsics.height_px;

  slapse::FrontEnd front_end(gt->intrinsics, 0.25);
  slapse::server::FrameOverlays overlays;
  (void)overlays.Png(slapse::server::OverlayKind::kMotionVectors, 640);  // wanted from now on
  std::vector<double> keep_ms, mv_ms, planes_ms, mv_kb, planes_kb;
  for (slapse::FrameRecord& f : frames) {
    auto step = front_end.Push(f);
    if (!slapse::IsAnchor(f.type)) continue;
    double t0 = ThreadCpuMs();
    overlays.SetAnchor(std::move(f), w, h);
    if (step.has_value() && step->extraction.ok()) {
      overlays.SetPlanes(step->pair.earlier_index, step->pair.later_index,
                         step->extraction->planes);
    }
    keep_ms.push_back(ThreadCpuMs() - t0);
    t0 = ThreadCpuMs();
    auto mv = overlays.Png(slapse::server::OverlayKind::kMotionVectors, 640);
    const double t1 = ThreadCpuMs();
    auto planes = overlays.Png(slapse::server::OverlayKind::kPlanes, 640);
    const double t2 = ThreadCpuMs();
    if (mv.ok()) {
      mv_ms.push_back(t1 - t0);
      mv_kb.push_back(mv->png.size() / 1024.0);
    }
    if (planes.ok()) {
      planes_ms.push_back(t2 - t1);
      planes_kb.push_back(planes->png.size() / 1024.0);
    }
  }
  std::printf("overlay_bench: %s, %dx%d, %zu frames, %zu anchors (medians, thread CPU time)\n\n",
              input.c_str(), w, h, frames.size(), keep_ms.size());
  std::printf("| measure | value |\n|---|---:|\n");
  std::printf("| reader per frame, keep_luma off (best of 3) | %.3f ms |\n", read_ms);
  std::printf("| reader per frame, keep_luma on (best of 3) | %.3f ms |\n", read_luma_ms);
  std::printf("| runner per anchor while watched (SetAnchor + SetPlanes) | %.3f ms |\n",
              Median(keep_ms));
  std::printf("| MV picture per anchor (draw, scale to 640 px, PNG) | %.2f ms, %.0f KiB |\n",
              Median(mv_ms), Median(mv_kb));
  std::printf("| planes picture per anchor (draw, scale to 640 px, PNG) | %.2f ms, %.0f KiB |\n",
              Median(planes_ms), Median(planes_kb));
  return 0;
}
