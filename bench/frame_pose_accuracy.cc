// frame_pose_accuracy: per-frame poses against the simulator's truth, per
// drive, for one or more settings of the frame-pose estimator.
//
//   build/bench/frame_pose_accuracy --seeds 1,2,3 --duration 5 [--dir /tmp/fpa]
//       [--prior-rot 0.01,0] [--prior-pos 0,0.05] [--extra-sigma 1.0] [--min-inliers 20]
//
// Simulates each seed's drive once into DIR/seedN (640x480 MPEG-2 IBBBP, the
// simulator's defaults; reused when there), runs the pipeline for each
// combination of the listed settings and prints one Markdown row per drive
// and setting: poses, position RMSE (m) of the anchors, of the FRAME poses,
// of the same frames interpolated between their anchors instead, the number
// of INTERPOLATED frames, the largest error of any pose, and the share of the
// pipeline's stage time spent posing frames. Errors are in the anchors' own
// Sim(3) alignment (lab/eval/frame_pose_eval.h). Choose settings on tuning
// seeds, report on others (docs/TRAJECTORY.md "Per-frame poses").
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "core/common/intrinsics_io.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "lab/eval/frame_pose_eval.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/simulate.h"

namespace {

std::vector<double> ParseList(const std::string& s) {
  std::vector<double> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(std::atof(item.c_str()));
  return out;
}

struct Drive {
  std::string dir, video;
  slapse::Intrinsics intrinsics;
};

bool Prepare(uint64_t seed, double duration_s, const std::string& root, Drive* d) {
  d->dir = root + "/seed" + std::to_string(seed);
  if (!std::filesystem::exists(d->dir + "/meta.json")) {
    slapse::SimulateOptions o;
    o.seed = seed;
    o.duration_s = duration_s;
    o.output_dir = d->dir;
    slapse::SimulateReport report;
    slapse::Status s = slapse::SimulateDrive(o, &report);
    if (!s.ok()) {
      std::fprintf(stderr, "seed %llu: %s\n", static_cast<unsigned long long>(seed),
                   s.ToString().c_str());
      return false;
    }
  }
  d->video = d->dir + "/drive.ts";
  auto k = slapse::ReadIntrinsicsJson(d->dir + "/intrinsics.json");
  if (!k.ok()) return false;
  d->intrinsics = *k;
  return true;
}

void RunOne(uint64_t seed, const Drive& d, const slapse::FramePoseOptions& fo,
            const std::vector<slapse::TimedPose>& truth) {
  auto reader = slapse::MvReader::Open(d.video);
  if (!reader.ok()) return;
  slapse::PipelineOptions po;
  po.frame_poses.estimator = fo;
  slapse::Intrinsics k = d.intrinsics;
  k.width_px = (*reader)->info().width_px;
  k.height_px = (*reader)->info().height_px;
  slapse::Pipeline pipeline(k, (*reader)->info().mv_sigma_px(), po);
  slapse::FrameRecord f;
  double stage_ms = 0, frame_ms = 0;
  long frames = 0;
  while ((*reader)->Next(&f).ok()) {
    ++frames;
    auto step = pipeline.Push(f);
    if (!step.ok() || !step->has_value()) continue;
    const slapse::StageTimes& t = (*step)->times;
    stage_ms += t.merge_ms + t.threshold_ms + t.fit_ms + t.ekf_ms + t.frame_poses_ms;
    frame_ms += t.frame_poses_ms;
  }
  auto e = slapse::EvaluateFramePoses(pipeline.poses(), truth);
  if (!e.ok()) {
    std::printf("| %llu | %s |\n", static_cast<unsigned long long>(seed),
                e.status().ToString().c_str());
    return;
  }
  std::printf(
      "| %llu | %.3g | %.2g | %.2g | %ld | %zu | %.3f | %.3f (%d) | %.3f | %.4f | %.4f | %.3f | "
      "%.3f | %.3f | %d | %.3f | %.3f | %.1f %% |\n",
      static_cast<unsigned long long>(seed), fo.prior_rotation_rad, fo.prior_position_rel,
      fo.extra_sigma_px, frames, pipeline.poses().size(), e->anchor.rmse_m, e->frame.rmse_m,
      e->frame.poses, e->frame_baseline.rmse_m, e->frame_local.rmse_m,
      e->frame_baseline_local.rmse_m, e->anchors.rpe_rot_rmse_deg, e->frame_local.rot_rmse_deg,
      e->frame_baseline_local.rot_rmse_deg, e->interpolated.poses, e->anchor.max_m, e->all.max_m,
      stage_ms > 0 ? 100.0 * frame_ms / stage_ms : 0.0);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  // The settings default to FramePoseOptions' own.
  const slapse::FramePoseOptions defaults;
  std::string seeds = "1,2,3", dir = "/tmp/frame_pose_accuracy",
              prior_rot = std::to_string(defaults.prior_rotation_rad),
              extra = std::to_string(defaults.extra_sigma_px),
              prior_pos = std::to_string(defaults.prior_position_rel);
  double duration_s = 5.0;
  int min_inliers = defaults.min_inliers;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i], v = argv[i + 1];
    if (a == "--seeds")
      seeds = v;
    else if (a == "--duration")
      duration_s = std::atof(v.c_str());
    else if (a == "--dir")
      dir = v;
    else if (a == "--prior-rot")
      prior_rot = v;
    else if (a == "--extra-sigma")
      extra = v;
    else if (a == "--prior-pos")
      prior_pos = v;
    else if (a == "--min-inliers")
      min_inliers = std::atoi(v.c_str());
    else {
      std::fprintf(stderr, "unknown flag %s (see the header of bench/frame_pose_accuracy.cc)\n",
                   a.c_str());
      return 2;
    }
  }
  std::printf(
      "| seed | prior rot | prior pos | extra sigma | frames | poses | anchors RMSE m | FRAME "
      "RMSE m (n) | same frames interpolated m | FRAME local m | interpolated local m | anchors "
      "RPE rot deg | FRAME local rot deg | interpolated local rot deg | INTERPOLATED | anchors max "
      "error m | max error m | frame-pose share of stage time |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
      "\n");
  for (double seed_d : ParseList(seeds)) {
    const uint64_t seed = static_cast<uint64_t>(seed_d);
    Drive d;
    if (!Prepare(seed, duration_s, dir, &d)) return 1;
    auto gt = slapse::LoadGroundTruth(d.dir);
    if (!gt.ok()) return 1;
    const auto truth = slapse::TruthPoses(*gt);
    for (double pr : ParseList(prior_rot)) {
      for (double pp : ParseList(prior_pos)) {
        for (double ex : ParseList(extra)) {
          slapse::FramePoseOptions fo;
          fo.prior_rotation_rad = pr;
          fo.prior_position_rel = pp;
          fo.extra_sigma_px = ex;
          fo.min_inliers = min_inliers;
          if (!fo.Check().ok()) return 2;
          RunOne(seed, d, fo, truth);
        }
      }
    }
  }
  return 0;
}
