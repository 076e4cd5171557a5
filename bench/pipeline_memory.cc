// pipeline_memory: does a pipeline's memory grow with the length of its
// stream? One simulated drive's frames are pushed again and again (each loop
// shifted in frame index and time, with a Break() between loops, as a camera
// that reconnects) for the given stream duration, the server's way
// (Pipeline::ForgetFinal after every step, SessionManagerOptions's
// final_poses_in_memory) or `run`'s (--keep -1: nothing forgotten). Prints,
// ten times over the run, what the pipeline holds and the process's RSS.
//
//   build/bench/pipeline_memory                  # 1 h of stream, keep 256
//   build/bench/pipeline_memory --hours 1 --keep -1
//
// Timing and memory live here, never in tests.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench/rss.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/simulate.h"

namespace {}  // namespace

int main(int argc, char** argv) {
  CLI::App app("pipeline_memory: a pipeline's memory over a long stream");
  double hours = 1.0;
  long keep = 256;
  app.add_option("--hours", hours, "stream duration to push (loops of a 10 s drive)")
      ->capture_default_str();
  app.add_option("--keep", keep, "final poses kept (Pipeline::ForgetFinal); -1: forget nothing")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  slapse::SimulateOptions sim;
  sim.output_dir = (std::filesystem::temp_directory_path() / "slapse_memory_drive").string();
  slapse::SimulateReport rep;
  if (slapse::Status s = slapse::SimulateDrive(sim, &rep); !s.ok()) {
    std::fprintf(stderr, "pipeline_memory: %s\n", s.ToString().c_str());
    return 1;
  }
  auto gt = slapse::LoadGroundTruth(sim.output_dir);
  auto reader = slapse::MvReader::Open(rep.video_path);
  if (!gt.ok() || !reader.ok()) {
    std::fprintf(stderr, "pipeline_memory: cannot read the simulated drive\n");
    return 1;
  }
  std::vector<slapse::FrameRecord> frames;
  slapse::FrameRecord f;
  while ((*reader)->Next(&f).ok()) frames.push_back(f);
  const double sigma_px = (*reader)->info().mv_sigma_px();
  reader->reset();
  if (frames.size() < 2) return 1;
  const double loop_s = frames.back().timestamp_s + (frames[1].timestamp_s - frames[0].timestamp_s);
  const long loops = std::max(1L, static_cast<long>(hours * 3600 / loop_s));

  slapse::Pipeline pipeline(gt->intrinsics, sigma_px);
  std::printf("drive: %zu frames (%.1f s) pushed %ld times (%.2f h of stream), keep %ld\n\n",
              frames.size(), loop_s, loops, loops * loop_s / 3600, keep);
  std::printf(
      "| stream (h) | poses held | anchors held | planes held | poses forgotten | RSS (MiB) |\n");
  std::printf("|---:|---:|---:|---:|---:|---:|\n");
  const int64_t n = static_cast<int64_t>(frames.size());
  for (long loop = 0; loop < loops; ++loop) {
    if (loop > 0) pipeline.Break();
    for (slapse::FrameRecord frame : frames) {
      const int64_t shift = loop * n;
      frame.index += shift;
      if (frame.prev_anchor_index >= 0) frame.prev_anchor_index += shift;
      if (frame.next_anchor_index >= 0) frame.next_anchor_index += shift;
      if (frame.coded_index >= 0) frame.coded_index += shift;
      frame.timestamp_s += loop * loop_s;
      auto step = pipeline.Push(frame);
      if (!step.ok()) {
        std::fprintf(stderr, "pipeline_memory: %s\n", step.status().ToString().c_str());
        return 1;
      }
      if (step->has_value() && keep >= 0) pipeline.ForgetFinal(static_cast<size_t>(keep));
    }
    if ((loop + 1) % std::max(1L, loops / 10) == 0 || loop + 1 == loops) {
      std::printf("| %.2f | %zu | %zu | %zu | %zu | %.1f |\n", (loop + 1) * loop_s / 3600,
                  pipeline.poses().size(), pipeline.trajectory().size(),
                  pipeline.plane_map().size(), pipeline.poses_forgotten(),
                  slapse::bench::RssKb() / 1024.0);
      std::fflush(stdout);
    }
  }
  return 0;
}
