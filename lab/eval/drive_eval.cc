#include "lab/eval/drive_eval.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <sstream>

#include "core/common/timing.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/result_io.h"
#include "lab/eval/plane_map_eval.h"
#include "lab/eval/trajectory_eval.h"
#include "lab/gt/ground_truth.h"

namespace slapse {

Status DriveEvalOptions::Check() const {
  if (out_dir.empty()) return InvalidArgumentError("drive evaluation needs an output directory");
  if (true_vectors) SLAPSE_RETURN_IF_ERROR(true_vector.Check());
  return EncoderProfile(profile).status();
}

namespace {

using Clock = std::chrono::steady_clock;

// One pipeline run over the drive's frame records.
struct Run {
  std::vector<TimedPose> poses;        // the anchors' (Pipeline::trajectory())
  std::vector<TimedPose> frame_poses;  // every posed frame (Pipeline::poses())
  std::vector<PlaneEstimate> planes;
  bool metric = false;
  PipelineStepCounts counts;    // extended: pairs handed back for a longer baseline
  int motion_only_anchors = 0;  // anchors posed without a plane (PoseKind::kMotionOnly)
  int coasting_anchors = 0;     // anchors posed by the motion model (PoseKind::kCoasting)
  int full_motion_fits = 0;     // pairs whose motion took the full path (PipelineStep::motion_path)
  ScaleSupport scale_support;
  std::optional<double> height_road_depression_deg;  // Pipeline's, when metric from the height
  std::map<std::string, int> notes;
};

StatusOr<Run> RunPipeline(const std::vector<FrameRecord>& frames, const Intrinsics& intrinsics,
                          double sigma_px, const PipelineOptions& options) {
  Run run;
  Pipeline pipeline(intrinsics, sigma_px, options);
  auto record = [&](const PipelineStep& s) {
    if (!s.tracking && !s.extended && !s.note.empty()) ++run.notes[s.note];
    run.full_motion_fits += s.motion_path == PairMotionPath::kFullFit;
    AppendPlaneEstimates(s.later_index, s.planes, s.extracted, s.extracted_filter_ids, &run.planes);
  };
  for (const FrameRecord& f : frames) {
    auto step = pipeline.Push(f);
    if (!step.ok()) return step.status();
    if (step->has_value()) {
      run.counts.Add(**step);
      record(**step);
    }
  }
  // A pair still handed back at the end: processed as it is.
  if (std::optional<PipelineStep> last = pipeline.Finish(); last.has_value()) {
    run.counts.AddFinish(*last);
    record(*last);
  }
  for (const auto& p : pipeline.trajectory()) run.poses.push_back(p);
  run.frame_poses = TimedPosesOf(pipeline.poses());
  for (const FramePose& p : pipeline.poses()) {
    run.motion_only_anchors += p.quality.kind == PoseKind::kMotionOnly;
    run.coasting_anchors += p.quality.kind == PoseKind::kCoasting;
  }
  run.metric = pipeline.metric();
  run.height_road_depression_deg = pipeline.height_road_depression_deg();
  run.scale_support = pipeline.scale_support();
  return run;
}

// Simulates the drive into dir unless it is there already (meta.json written last).
Status EnsureSimulated(const DriveSpec& spec, const EncoderOptions& encoder, const std::string& dir,
                       bool reuse) {
  if (reuse && std::filesystem::exists(std::filesystem::path(dir) / "meta.json")) {
    return Status::Ok();
  }
  SimulateOptions o = spec.sim;
  o.encoder = encoder;
  o.output_dir = dir;
  SimulateReport report;
  return SimulateDrive(o, &report);
}

// True speed (m/s) at frame i by central differences of the true positions.
double TrueSpeed(const GroundTruth& gt, size_t i) {
  const size_t a = i > 0 ? i - 1 : i, b = std::min(i + 1, gt.frames.size() - 1);
  if (b == a) return 0.0;
  const double dt = gt.frames[b].timestamp_s - gt.frames[a].timestamp_s;
  return (gt.frames[b].world_from_cam.translation - gt.frames[a].world_from_cam.translation)
             .norm() /
         dt;
}

// Fills the scale source's entry of `r` from a metric run.
void ScoreScale(const Run& run, const std::vector<TimedPose>& truth, int source, DriveResult* r) {
  r->metric[source] = run.metric;
  if (!run.metric) return;
  auto e = EvaluateTrajectory(run.poses, truth);
  if (!e.ok()) {
    r->metric[source] = false;
    return;
  }
  r->scale_error[source] = e->sim3_scale - 1.0;
  if (source == kScaleCameraHeight) {
    r->height_road_depression_deg = run.height_road_depression_deg.value_or(NAN);
  }
}

}  // namespace

StatusOr<DriveResult> EvaluateDrive(const DriveSpec& spec, const DriveEvalOptions& options) {
  SLAPSE_RETURN_IF_ERROR(options.Check());
  DriveResult r;
  r.spec = spec;
  const std::string dir =
      (std::filesystem::path(options.out_dir) / options.profile / spec.name).string();
  const auto t0 = Clock::now();
  SLAPSE_RETURN_IF_ERROR(
      EnsureSimulated(spec, *EncoderProfile(options.profile, spec.sim.fps), dir, options.reuse));
  const auto t1 = Clock::now();
  r.simulate_s = SecondsBetween(t0, t1);

  auto gt = LoadGroundTruth(dir);
  if (!gt.ok()) return gt.status();
  auto reader = MvReader::Open(dir + "/" + spec.sim.video_name);
  if (!reader.ok()) return reader.status();
  std::vector<FrameRecord> frames;
  FrameRecord f;
  Status end;
  while ((end = (*reader)->Next(&f)).ok()) frames.push_back(f);
  if (end.code() != StatusCode::kOutOfRange) return end;
  if (options.true_vectors) {
    TrueVectorReport replaced;
    SLAPSE_RETURN_IF_ERROR(ReplaceWithTrueVectors(*gt, options.true_vector, &frames, &replaced));
  }
  const double sigma = (*reader)->info().mv_sigma_px();
  const std::vector<TimedPose> truth = TruthPoses(*gt);
  r.frames = static_cast<int>(frames.size());
  for (size_t i = 1; i < truth.size(); ++i) {
    r.drive_distance_m +=
        (truth[i].world_from_cam.translation - truth[i - 1].world_from_cam.translation).norm();
  }

  PipelineOptions po = options.pipeline;
  po.scale = ScaleOptions{};
  auto base = RunPipeline(frames, gt->intrinsics, sigma, po);
  if (!base.ok()) return base.status();
  r.posed_frames = static_cast<int>(base->frame_poses.size());
  r.anchor_pairs = base->counts.pairs;
  r.tracked_pairs = base->counts.tracked;
  r.motion_only_anchors = base->motion_only_anchors;
  r.coasting_anchors = base->coasting_anchors;
  r.full_motion_fits = base->full_motion_fits;
  r.extended_pairs = base->counts.extended;
  r.scale_support = base->scale_support;
  int most = 0;
  for (const auto& [note, n] : base->notes) {
    if (n > most) most = n, r.note = note;
  }
  if (!base->frame_poses.empty()) {
    r.first_pose_frame = base->frame_poses.front().index;
    r.first_pose_s = base->frame_poses.front().timestamp_s;
  }
  // ATE over every posed frame (what a user gets); eps_D (the paper's
  // metric), RPE per anchor step and the first-step scale over the anchors.
  auto errors = EvaluateTrajectory(base->poses, truth);
  auto frame_errors = EvaluateTrajectory(base->frame_poses, truth);
  if (errors.ok() && frame_errors.ok()) {
    r.evaluated = true;
    r.distance_m = frame_errors->distance_m;
    r.ate_m = frame_errors->ate_rmse_m;
    r.anchor_ate_m = errors->ate_rmse_m;
    r.eps_D = errors->eps_D;
    r.rpe_m = errors->rpe_trans_rmse_m;
    r.rpe_deg = errors->rpe_rot_rmse_deg;
    auto map = EvaluatePlaneMap(base->planes, *gt, errors->first_step_scale);
    if (map.ok() && map->planes_evaluated > 0) {
      r.planes_evaluated = map->planes_evaluated;
      r.eps_d_m = map->eps_d_m;
      r.eps_n_deg = map->eps_n_deg;
    }
    // The metric sources, each given the truth it asks for.
    const size_t i0 = static_cast<size_t>(base->poses[0].index);
    const size_t i1 = static_cast<size_t>(base->poses[1].index);
    ScaleOptions height, speed, first;
    height.source = ScaleOptions::Source::kCameraHeight;
    height.camera_height_m = gt->frames[0].world_from_cam.translation.z();
    speed.source = ScaleOptions::Source::kSpeed;
    speed.speed_mps = TrueSpeed(*gt, i0);
    first.source = ScaleOptions::Source::kFirstStep;
    first.first_step_m =
        (truth[i1].world_from_cam.translation - truth[i0].world_from_cam.translation).norm();
    const ScaleOptions sources[kNumScaleSources] = {height, speed, first};
    for (int k = 0; k < kNumScaleSources; ++k) {
      po.scale = sources[k];
      auto run = RunPipeline(frames, gt->intrinsics, sigma, po);
      if (!run.ok()) return run.status();
      ScoreScale(*run, truth, k, &r);
    }
  }
  r.evaluate_s = SecondsBetween(t1, Clock::now());
  return r;
}

namespace {

std::string Fmt(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), fmt, v);
  return buf;
}

std::string ScaleCell(const DriveResult& r, int k) {
  if (!r.evaluated) return "-";
  if (!r.metric[k]) return "not metric";
  // The camera height's scale the pipeline reported weak.
  const bool weak =
      k == kScaleCameraHeight && ScaleOptions::HeightScaleWeak(r.height_road_depression_deg);
  return Fmt("%+.1f %%", 100 * r.scale_error[k]) + (weak ? " (weak)" : "");
}

double Median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double Worst(const std::vector<double>& v) {
  return v.empty() ? NAN : *std::max_element(v.begin(), v.end());
}

std::string SplitTable(const std::vector<DriveResult>& results, DriveSplit split) {
  std::ostringstream md;
  md << "| drive | fps | size | frames | posed | first pose | D (m) | ATE (m) | ATE % | anchors' "
        "ATE % | eps_D "
        "| scale: height | scale: speed | scale: first step | eps_d (m) | eps_n (deg) | RPE (m / "
        "deg) |\n";
  md << "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  std::vector<double> ate_pct, eps_D, posed, epsd, epsn, scale[kNumScaleSources];
  std::vector<double> weak_ate, weak_eps_D, held_ate, held_eps_D;  // by ScaleSupport::Weak
  // |height scale error| % by how steeply the image saw the road
  // (ScaleOptions::HeightScaleWeak).
  std::vector<double> steep_height, shallow_height;
  int missing = 0, n = 0;
  for (const DriveResult& r : results) {
    if (r.spec.split != split) continue;
    ++n;
    const SimulateOptions& o = r.spec.sim;
    md << "| " << r.spec.name << " | " << Fmt("%.0f", o.fps) << " | " << o.width_px << "x"
       << o.height_px << " | " << r.frames << " | " << r.posed_frames << " | "
       << (r.first_pose_frame >= 0 ? Fmt("%.2f s", r.first_pose_s) : "never") << " | "
       << Fmt("%.1f", r.drive_distance_m) << " | ";
    posed.push_back(r.frames > 0 ? static_cast<double>(r.posed_frames) / r.frames : 0.0);
    if (!r.evaluated) {
      ++missing;
      md << "- | - | - | - | - | - | - | - | - | - |\n";
      continue;
    }
    const double pct = r.distance_m > 0 ? 100 * r.ate_m / r.distance_m : NAN;
    ate_pct.push_back(pct);
    eps_D.push_back(100 * r.eps_D);
    (r.scale_support.Weak() ? weak_ate : held_ate).push_back(pct);
    (r.scale_support.Weak() ? weak_eps_D : held_eps_D).push_back(100 * r.eps_D);
    for (int k = 0; k < kNumScaleSources; ++k) {
      if (r.metric[k]) scale[k].push_back(100 * std::abs(r.scale_error[k]));
    }
    if (r.metric[kScaleCameraHeight]) {
      (ScaleOptions::HeightScaleWeak(r.height_road_depression_deg) ? shallow_height : steep_height)
          .push_back(100 * std::abs(r.scale_error[kScaleCameraHeight]));
    }
    if (r.planes_evaluated > 0) {
      epsd.push_back(r.eps_d_m);
      epsn.push_back(r.eps_n_deg);
    }
    const double anchor_pct = r.distance_m > 0 ? 100 * r.anchor_ate_m / r.distance_m : NAN;
    md << Fmt("%.3f", r.ate_m) << " | " << Fmt("%.2f %%", pct) << " | "
       << Fmt("%.2f %%", anchor_pct) << " | " << Fmt("%.2f %%", 100 * r.eps_D) << " | "
       << ScaleCell(r, 0) << " | " << ScaleCell(r, 1) << " | " << ScaleCell(r, 2) << " | "
       << (r.planes_evaluated > 0 ? Fmt("%.2f", r.eps_d_m) : "-") << " | "
       << (r.planes_evaluated > 0 ? Fmt("%.2f", r.eps_n_deg) : "-") << " | " << Fmt("%.3f", r.rpe_m)
       << " / " << Fmt("%.3f", r.rpe_deg) << " |\n";
  }
  auto mw = [](const std::vector<double>& v, const char* f) {
    return v.empty() ? std::string("-") : Fmt(f, Median(v)) + " / " + Fmt(f, Worst(v));
  };
  md << "\n"
     << n << " drives, " << missing << " with fewer than 3 poses (not scored). "
     << "Median / worst over the scored drives: ATE " << mw(ate_pct, "%.2f %%") << ", eps_D "
     << mw(eps_D, "%.2f %%") << ", |scale error| height " << mw(scale[0], "%.1f %%") << " ("
     << scale[0].size() << " metric), speed " << mw(scale[1], "%.1f %%") << " (" << scale[1].size()
     << " metric), first step " << mw(scale[2], "%.1f %%") << " (" << scale[2].size()
     << " metric), eps_d " << mw(epsd, "%.2f m") << ", eps_n " << mw(epsn, "%.2f deg")
     << "; frames posed: median "
     << (posed.empty() ? std::string("-") : Fmt("%.0f %%", 100 * Median(posed))) << ".\n";
  if (!ate_pct.empty()) {
    md << "\nScale support (ScaleSupport, docs/TRAJECTORY.md \"Scale support\"): "
       << weak_ate.size() << " scored drives with planes measuring fewer than "
       << Fmt("%.0f %%", 100 * ScaleSupport::kMinPlaneStepShare) << " of their anchor steps, ATE "
       << mw(weak_ate, "%.2f %%") << ", eps_D " << mw(weak_eps_D, "%.2f %%") << "; the other "
       << held_ate.size() << ", ATE " << mw(held_ate, "%.2f %%") << ", eps_D "
       << mw(held_eps_D, "%.2f %%") << ".\n";
  }
  if (!scale[kScaleCameraHeight].empty()) {
    auto beyond3 = [](const std::vector<double>& v) {
      return std::count_if(v.begin(), v.end(), [](double e) { return e > 3.0; });
    };
    md << "\nHeight scale by how steeply the image saw the road (Pipeline::"
          "height_road_depression_deg): "
       << steep_height.size() << " metric runs at "
       << Fmt("%.0f deg", ScaleOptions::kMinRoadDepressionDeg) << " or steeper, |scale error| "
       << mw(steep_height, "%.1f %%") << ", " << beyond3(steep_height) << " beyond 3 %; "
       << shallow_height.size() << " shallower (reported weak), " << mw(shallow_height, "%.1f %%")
       << ", " << beyond3(shallow_height) << " beyond 3 %.\n";
  }
  return md.str();
}

}  // namespace

std::string DriveResultsMarkdown(const std::vector<DriveResult>& results,
                                 const std::string& profile) {
  std::ostringstream md;
  for (DriveSplit split : {DriveSplit::kTuning, DriveSplit::kReporting}) {
    md << "### " << DriveSplitName(split) << " drives (" << profile << ")\n\n"
       << SplitTable(results, split) << "\n";
  }
  // Why pairs did not track, per drive that missed poses.
  md << "Drives with frames before their first pose or untracked pairs (the most frequent "
        "reason):\n\n";
  for (const DriveResult& r : results) {
    if (r.tracked_pairs == r.anchor_pairs && r.first_pose_frame >= 0 && r.first_pose_s < 1.0) {
      continue;
    }
    md << "- " << r.spec.name << ": " << r.tracked_pairs << " of " << r.anchor_pairs
       << " anchor pairs tracked, first pose "
       << (r.first_pose_frame >= 0 ? Fmt("at %.2f s", r.first_pose_s) : std::string("never"))
       << (r.note.empty() ? "" : "; \"" + r.note + "\"") << "\n";
  }
  // Where the planes did not carry the trajectory.
  md << "\nDrives with motion-only anchors (no plane observed: rotation and direction from the "
        "pair, step length from the motion model):\n\n";
  for (const DriveResult& r : results) {
    if (r.motion_only_anchors == 0) continue;
    md << "- " << r.spec.name << ": " << r.motion_only_anchors << " of " << r.tracked_pairs
       << " tracked anchors\n";
  }
  return md.str();
}

std::string DriveResultsCsv(const std::vector<DriveResult>& results) {
  std::ostringstream csv;
  csv << "drive,kind,seed,split,fps,width,height,frames,posed_frames,first_pose_frame,"
         "first_pose_s,anchor_pairs,tracked_pairs,drive_distance_m,evaluated,distance_m,ate_m,"
         "ate_pct,anchor_ate_m,eps_D,rpe_m,rpe_deg,planes_evaluated,eps_d_m,eps_n_deg,metric_"
         "height,"
         "scale_err_height,metric_speed,scale_err_speed,metric_first_step,scale_err_first_step,"
         "camera_height_m,pitch_down_deg,simulate_s,evaluate_s,note,motion_only_anchors,coasting_"
         "anchors,extended_pairs,plane_step_share,height_road_depression_deg,full_motion_fits,"
         "bounce_m\n";
  for (const DriveResult& r : results) {
    const SimulateOptions& o = r.spec.sim;
    std::string note = r.note;
    std::replace(note.begin(), note.end(), '"', '\'');
    csv << r.spec.name << "," << SceneKindName(r.spec.kind) << "," << r.spec.seed << ","
        << DriveSplitName(r.spec.split) << "," << o.fps << "," << o.width_px << "," << o.height_px
        << "," << r.frames << "," << r.posed_frames << "," << r.first_pose_frame << ","
        << r.first_pose_s << "," << r.anchor_pairs << "," << r.tracked_pairs << ","
        << r.drive_distance_m << "," << (r.evaluated ? 1 : 0) << "," << r.distance_m << ","
        << r.ate_m << "," << (r.distance_m > 0 ? 100 * r.ate_m / r.distance_m : 0.0) << ","
        << r.anchor_ate_m << "," << r.eps_D << "," << r.rpe_m << "," << r.rpe_deg << ","
        << r.planes_evaluated << "," << r.eps_d_m << "," << r.eps_n_deg;
    for (int k = 0; k < kNumScaleSources; ++k) {
      csv << "," << (r.metric[k] ? 1 : 0) << "," << r.scale_error[k];
    }
    csv << "," << o.camera_height_min_m << "," << o.pitch_down_min_deg << "," << r.simulate_s << ","
        << r.evaluate_s << ",\"" << note << "\"," << r.motion_only_anchors << ","
        << r.coasting_anchors << "," << r.extended_pairs << "," << r.scale_support.PlaneStepShare()
        << "," << r.height_road_depression_deg << "," << r.full_motion_fits << "," << o.bounce_m
        << "\n";
  }
  return csv.str();
}

}  // namespace slapse
