// refine_eval: the pipeline with and without the window refiner (core/refine)
// on simulated drives, up to scale and with the camera height as scale source.
//
//   build/bench/refine_eval --seeds 1,2,3,4,5 --duration-s 5
//
// Each seed is simulated once into out/refine_eval/seedN (MPEG-2 IBBBP,
// 640x480 @ 30 fps, the simulator's defaults) and reused. Per drive and
// configuration: poses, eps_D, ATE (m and % of the distance), the largest
// step-to-step jump of the step-length ratio to the truth, the metric scale
// error (camera height: Sim(3) scale - 1, or "n/o" when the scale never
// became observable) and the mean refinement time per anchor pair. Timing
// here is wall time on whatever the machine is doing: compare configurations
// of one run, not runs.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "lab/eval/trajectory_eval.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/simulate.h"

namespace slapse {
namespace {

struct RunResult {
  bool ok = false;
  int poses = 0;
  TrajectoryErrors errors;
  double max_jump = 0;  // largest |ratio_k / ratio_{k-1} - 1| of step-length ratios
  bool metric = false;
  double refine_ms = 0, ekf_ms = 0;  // mean per tracked pair
  double wall_s = 0;
  double cpu_s = 0;  // process CPU time (std::clock), less sensitive to other load than wall time
};

// CPU seconds of the MV reader alone over the drive (decode + MV export).
double ReaderCpuS(const std::string& dir) {
  const std::clock_t c0 = std::clock();
  auto reader = MvReader::Open(dir + "/drive.ts");
  if (!reader.ok()) return 0;
  FrameRecord frame;
  while ((*reader)->Next(&frame).ok()) {
  }
  return static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
}

RunResult Run(const std::string& dir, const GroundTruth& gt, const std::vector<TimedPose>& truth,
              const PipelineOptions& options) {
  RunResult r;
  const auto t0 = std::chrono::steady_clock::now();
  const std::clock_t c0 = std::clock();
  auto reader = MvReader::Open(dir + "/drive.ts");
  if (!reader.ok()) return r;
  Pipeline pipeline(gt.intrinsics, (*reader)->info().mv_sigma_px(), options);
  FrameRecord frame;
  int tracked = 0;
  while ((*reader)->Next(&frame).ok()) {
    auto step = pipeline.Push(frame);
    if (!step.ok()) return r;
    if (!step->has_value() || !(*step)->tracking) continue;
    ++tracked;
    r.refine_ms += (*step)->times.refine_ms;
    r.ekf_ms += (*step)->times.ekf_ms;
  }
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.cpu_s = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
  if (tracked > 0) {
    r.refine_ms /= tracked;
    r.ekf_ms /= tracked;
  }
  auto errors = EvaluateTrajectory(pipeline.trajectory(), truth);
  if (!errors.ok()) return r;
  r.ok = true;
  r.errors = *errors;
  r.poses = static_cast<int>(pipeline.trajectory().size());
  r.metric = pipeline.metric();
  r.max_jump = MaxStepRatioJump(pipeline.trajectory(), truth, errors->sim3_scale);
  return r;
}

std::vector<uint64_t> ParseSeeds(const std::string& text) {
  std::vector<uint64_t> seeds;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) seeds.push_back(std::stoull(item));
  return seeds;
}

}  // namespace
}  // namespace slapse

int main(int argc, char** argv) {
  using namespace slapse;
  CLI::App app("refine_eval: the pipeline with and without the window refiner");
  std::string seeds_text = "1,2,3,4,5", out = "out/refine_eval";
  double duration_s = 5.0;
  int window = WindowRefinerOptions{}.window_anchors;
  bool cost_only = false;
  app.add_option("--seeds", seeds_text, "comma-separated simulator seeds")->capture_default_str();
  app.add_option("--duration-s", duration_s, "seconds per drive")->capture_default_str();
  app.add_option("--out", out, "where drives are simulated (reused)")->capture_default_str();
  app.add_option("--window", window, "refinement window (anchors)")->capture_default_str();
  app.add_flag("--cost-only", cost_only, "only the up-to-scale EKF and EKF+window runs");
  CLI11_PARSE(app, argc, argv);

  std::printf(
      "| drive | config | poses | eps_D | ATE (m) | ATE %% | max step-ratio jump | scale err | "
      "refine ms/pair | EKF ms/pair | wall s | CPU x reader |\n");
  std::printf("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (uint64_t seed : ParseSeeds(seeds_text)) {
    const std::string dir = out + "/seed" + std::to_string(seed);
    if (!std::filesystem::exists(dir + "/meta.json")) {
      SimulateOptions so;
      so.seed = seed;
      so.duration_s = duration_s;
      so.output_dir = dir;
      SimulateReport report;
      if (Status s = SimulateDrive(so, &report); !s.ok()) {
        std::fprintf(stderr, "seed %llu: %s\n", static_cast<unsigned long long>(seed),
                     s.ToString().c_str());
        continue;
      }
    }
    auto gt = LoadGroundTruth(dir);
    if (!gt.ok()) {
      std::fprintf(stderr, "%s: %s\n", dir.c_str(), gt.status().ToString().c_str());
      continue;
    }
    const std::vector<TimedPose> truth = TruthPoses(*gt);
    const double height_m = TrueCameraHeightM(*gt, 0);
    const double reader_cpu_s = ReaderCpuS(dir);
    for (int config = 0; config < (cost_only ? 2 : 4); ++config) {
      PipelineOptions o;
      o.window_refine = config % 2 == 1;
      o.refine.window_anchors = window;
      if (config >= 2) {
        o.scale.source = ScaleOptions::Source::kCameraHeight;
        o.scale.camera_height_m = height_m;
      }
      const RunResult r = Run(dir, *gt, truth, o);
      const char* name[] = {"EKF", "EKF+window", "EKF, height", "EKF+window, height"};
      if (!r.ok) {
        std::printf("| seed %llu | %s | failed |\n", static_cast<unsigned long long>(seed),
                    name[config]);
        continue;
      }
      char scale_err[32] = "-";
      if (config >= 2) {
        if (r.metric) {
          std::snprintf(scale_err, sizeof(scale_err), "%+.1f %%", 100 * (r.errors.sim3_scale - 1));
        } else {
          std::snprintf(scale_err, sizeof(scale_err), "n/o");
        }
      }
      std::printf(
          "| seed %llu | %s | %d | %.2f %% | %.3f | %.2f %% | %.1f %% | %s | %.2f | %.2f | %.1f "
          "| %.2f |\n",
          static_cast<unsigned long long>(seed), name[config], r.poses, 100 * r.errors.eps_D,
          r.errors.ate_rmse_m, 100 * r.errors.ate_rmse_m / std::max(r.errors.distance_m, 1e-9),
          100 * r.max_jump, scale_err, r.refine_ms, r.ekf_ms, r.wall_s,
          reader_cpu_s > 0 ? r.cpu_s / reader_cpu_s : 0.0);
      std::fflush(stdout);
    }
  }
  return 0;
}
