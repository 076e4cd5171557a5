// slapse run: the offline main job. A compressed video in; the camera
// trajectory (TUM, KITTI), the plane map (JSON) and a top-down plot out; with
// --gt (a simulated drive's directory) the errors against the ground truth.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>

#include <opencv2/imgcodecs.hpp>

#include "api/validate.h"
#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "core/common/intrinsics_io.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "core/pipeline/result_io.h"
#include "core/viz/plane_overlay.h"
#include "lab/eval/frame_pose_eval.h"
#include "lab/eval/plane_map_eval.h"
#include "lab/eval/trajectory_eval.h"
#include "lab/gt/ground_truth.h"
#include "lab/viz/top_down_plot.h"

namespace slapse::cli {
namespace {

// The trajectory files hold every posed frame (Pipeline::poses()), the
// quality CSV one row per line of the TUM file.
Status WriteResults(const Pipeline& pipeline, const std::string& dir) {
  const std::vector<TimedPose> traj = TimedPosesOf(pipeline.poses());
  SLAPSE_RETURN_IF_ERROR(WriteResultFile(
      dir + "/trajectory_tum.txt", [&](std::ostream& out) { WriteTrajectoryTum(traj, out); }));
  SLAPSE_RETURN_IF_ERROR(WriteResultFile(
      dir + "/trajectory_kitti.txt", [&](std::ostream& out) { WriteTrajectoryKitti(traj, out); }));
  SLAPSE_RETURN_IF_ERROR(WriteResultFile(dir + "/trajectory_quality.csv", [&](std::ostream& out) {
    WritePoseQualityCsv(pipeline.poses(), out);
  }));
  return WriteResultFile(dir + "/planes.json", [&](std::ostream& out) {
    WriteResultJson(pipeline.plane_map(), pipeline.metric(), ResultJsonOptions{}, out);
  });
}

using CsvFile = std::unique_ptr<std::FILE, int (*)(std::FILE*)>;

// --steps-csv with its header, or null if it cannot be written.
CsvFile OpenStepsCsv(const std::string& path) {
  CsvFile csv(std::fopen(path.c_str(), "w"), &std::fclose);
  if (csv) {
    std::fprintf(
        csv.get(),
        "later_index,tracking,step_length,kept,filter_planes,updated,added,removed,rejected,"
        "reassociated,reidentified,road_coasting,rms_residual_px,extracted,note,motion_path,"
        "road_from_frames\n");
  }
  return csv;
}

// One --steps-csv row for an anchor pair.
void WriteStepRow(std::FILE* csv, const PipelineStep& s, const std::vector<TimedPose>& traj) {
  // extracted: track_id:MBs:t(racked)/n(ew):track_change, space separated.
  std::string extracted;
  for (const ExtractedPlane& ex : s.extracted) {
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%s%d:%zu:%c:%.2f", extracted.empty() ? "" : " ", ex.track_id,
                  ex.mb_indices.size(), ex.tracked ? 't' : 'n', ex.track_change);
    extracted += buf;
  }
  const double length = traj.size() >= 2 ? (traj.back().world_from_cam.translation -
                                            traj[traj.size() - 2].world_from_cam.translation)
                                               .norm()
                                         : 0.0;
  // road_from_frames: the road in the B frames measured the step, or joined the filter.
  const char* road = s.ekf.road_step_updated        ? "measured"
                     : s.ekf.road_added_from_frames ? "added"
                                                    : "";
  std::fprintf(csv, "%lld,%d,%.4f,%d,%zu,%d,%d,%d,%d,%d,%d,%d,%.3f,%s,\"%s\",%s,%s\n",
               static_cast<long long>(s.later_index), s.tracking ? 1 : 0, length, s.kept,
               s.planes.size(), s.ekf.planes_updated, s.ekf.planes_added, s.ekf.planes_removed,
               s.ekf.planes_rejected, s.ekf.planes_reassociated, s.ekf.planes_reidentified,
               s.ekf.road_coasting ? 1 : 0, s.ekf.rms_residual_px, extracted.c_str(),
               s.note.c_str(), PairMotionPathName(s.motion_path), road);
}

// The truth in the top-down plot: its path and the facades' footprints on the road.
void DrawTruth(const GroundTruth& gt, const std::vector<TimedPose>& truth, TopDownPlot* plot) {
  std::vector<Eigen::Vector2d> gt_path;
  for (const TimedPose& t : truth) gt_path.push_back(t.world_from_cam.translation.head<2>());
  plot->AddPath(gt_path, cv::Scalar(60, 60, 60), "ground truth", 2);
  for (const GtPlane& p : gt.planes) {
    if (p.kind != PlaneKind::kFacade) continue;
    for (const auto& poly : p.polygons_world) {
      for (size_t i = 0; i + 1 < poly.size(); ++i) {
        if (std::abs(poly[i].z()) < 1e-6 && std::abs(poly[i + 1].z()) < 1e-6) {
          plot->AddSegment(poly[i].head<2>(), poly[i + 1].head<2>(), cv::Scalar(190, 190, 190), 3);
        }
      }
    }
  }
}

// Per-frame poses by kind, in the anchors' alignment (lab/eval/frame_pose_eval.h).
void PrintFramePoseErrors(const std::vector<FramePose>& poses,
                          const std::vector<TimedPose>& truth) {
  auto e = EvaluateFramePoses(poses, truth);
  if (!e.ok()) return;
  auto row = [](const char* name, const PositionErrorStats& s) {
    std::printf("  %-13s %5d poses  RMSE %.3f m  max %.3f m\n", name, s.poses, s.rmse_m, s.max_m);
  };
  std::printf("per-frame  position errors in the anchors' Sim(3) alignment:\n");
  row("anchors", e->anchor);
  row("frames", e->frame);
  row("(interp.)", e->frame_baseline);
  row("interpolated", e->interpolated);
  row("all", e->all);
}

void PrintErrors(const TrajectoryErrors& terr, const StatusOr<PlaneMapErrors>& perr) {
  std::printf("distance   %.1f m over %d poses\n", terr.distance_m, terr.poses);
  std::printf("eps_D      %.2f %%   (paper: mean relative position error, first-step scale)\n",
              100 * terr.eps_D);
  std::printf("ATE        %.3f m   (RMSE after Sim(3) alignment, scale %.3f m/unit)\n",
              terr.ate_rmse_m, terr.sim3_scale);
  std::printf("RPE        %.3f m, %.3f deg per anchor step (RMSE)\n", terr.rpe_trans_rmse_m,
              terr.rpe_rot_rmse_deg);
  if (perr.ok()) {
    std::printf("planes     %d evaluated (seen >= 0.5 s): eps_d %.2f m, eps_n %.2f deg\n",
                perr->planes_evaluated, perr->eps_d_m, perr->eps_n_deg);
  }
}

// map.png (the estimate in x-z of its world, the first camera, or aligned to
// the truth) and, with the truth, the errors on stdout.
void MapAndErrors(const Pipeline& pipeline, const std::optional<GroundTruth>& gt,
                  const std::vector<PlaneEstimate>& plane_estimates, const std::string& out_dir) {
  TopDownPlot plot;
  const Sim3d* align = nullptr;
  std::optional<TrajectoryErrors> terr;
  if (gt.has_value()) {
    std::vector<TimedPose> est;
    for (const auto& p : pipeline.trajectory())
      est.push_back({p.index, p.timestamp_s, p.world_from_cam});
    const std::vector<TimedPose> truth = TruthPoses(*gt);
    auto e = EvaluateTrajectory(est, truth);
    if (e.ok()) {
      terr = *e;
      align = &terr->truth_from_estimate;
      DrawTruth(*gt, truth, &plot);
    } else {
      std::printf("errors     not available: %s\n", e.status().ToString().c_str());
    }
  }
  auto to_map = [&](const Eigen::Vector3d& x) -> Eigen::Vector2d {
    if (align != nullptr) return ((*align) * x).head<2>();
    return Eigen::Vector2d(x.x(), x.z());  // camera world: x right, z forward
  };
  std::vector<Eigen::Vector2d> est_path;
  for (const auto& p : pipeline.trajectory())
    est_path.push_back(to_map(p.world_from_cam.translation));
  for (const auto& [id, mp] : pipeline.plane_map()) {
    std::vector<Eigen::Vector2d> pts;
    for (const Eigen::Vector3d& x : mp.support_world) pts.push_back(to_map(x));
    plot.AddPoints(std::move(pts), TrackColour(id), 1);
  }
  plot.AddPath(est_path, cv::Scalar(30, 30, 220), align ? "SLAPSE (Sim(3)-aligned)" : "SLAPSE", 2);
  const std::string unit = align != nullptr || pipeline.metric() ? "m" : "first steps";
  cv::imwrite(out_dir + "/map.png", plot.Render(900, 900, "trajectory and plane map", unit));
  if (terr.has_value()) {
    PrintErrors(*terr, EvaluatePlaneMap(plane_estimates, *gt, terr->first_step_scale));
    PrintFramePoseErrors(pipeline.poses(), TruthPoses(*gt));
  }
}

// The re-encoding (when the codec has no vectors) and its cost, and the
// stream's changes (resolution changes).
void PrintStreamReport(const StreamInfo& info, const ReadStats& stats) {
  const double frames = std::max<double>(1.0, static_cast<double>(stats.frames));
  if (!info.reencoded_from.empty()) {
    std::printf(
        "re-encoded from %s to %s for motion vectors: %.1f ms/frame CPU (decoding %s: %.1f "
        "ms/frame, %.1fx that)\n",
        info.reencoded_from.c_str(), info.codec_name.c_str(), 1e3 * stats.reencode_cpu_s / frames,
        info.reencoded_from.c_str(), 1e3 * stats.decode_cpu_s / frames,
        stats.decode_cpu_s > 0 ? stats.reencode_cpu_s / stats.decode_cpu_s : 0.0);
  }
  for (const std::string& note : stats.notes) std::printf("stream     %s\n", note.c_str());
}

}  // namespace

int RunRun(int argc, char** argv) {
  CommandLine cl("run", "INPUT [options]   (INPUT: a file path or URL)", "INPUT");
  CLI::App& app = cl.app();
  PipelineOptions po;
  std::string intrinsics_spec, gt_dir, steps_csv_path, out_dir = "out/run";
  app.add_option("--intrinsics", intrinsics_spec,
                 "FILE.json, 'fx,fy,cx,cy' or 'hfov=DEG' (default: intrinsics.json beside INPUT)")
      ->type_name("SPEC");
  app.add_option("--out", out_dir, "output directory")->type_name("DIR")->capture_default_str();
  app.add_option("--gt", gt_dir, "a simulated drive's directory: print errors, draw the truth")
      ->type_name("DIR");
  ScaleFlags scale_flags;
  scale_flags.AddTo(&cl);
  app.add_option("--eps-h", po.extraction.eps_h_px, "homography inlier threshold")
      ->type_name("PX")
      ->capture_default_str();
  app.add_option("--steps-csv", steps_csv_path,
                 "also write one CSV row per anchor pair: its planes and the filter's")
      ->type_name("FILE");
  AddTrackingFlags(&cl, &po);
  app.add_option("--init-max-baseline-s", po.init_max_baseline_s,
                 "while waiting to initialise, extend a one-frame IPPP pair too short to decide "
                 "the motion by the next frames up to this span; 0 = off (docs/METHOD.md)")
      ->type_name("S")
      ->check(CLI::Range(0.0, api::kMaxBaselineExtensionS))
      ->capture_default_str();
  app.add_option("--track-max-baseline-s", po.track_max_baseline_s,
                 "while tracking, extend such a pair by the next frames up to this span instead "
                 "of coasting on the motion model; 0 = off (docs/METHOD.md)")
      ->type_name("S")
      ->check(CLI::Range(0.0, api::kMaxBaselineExtensionS))
      ->capture_default_str();
  bool quiet = false;
  app.add_flag("--quiet", quiet, "no progress line");
  MvReaderOptions ro;
  bool no_reencode = !ro.reencode;
  app.add_flag("--no-reencode", no_reencode,
               "refuse a codec without motion vectors (HEVC, VP9, AV1, MJPEG, ...) instead of "
               "re-encoding it in-process");
  bool anchors_only = !po.frame_poses.enabled;
  app.add_flag("--anchors-only", anchors_only,
               "pose the anchor frames only (default: every frame between tracked anchors too)");
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  if (cl.positional().size() != 1) return Fail("run", "expected one INPUT (see --help)", 2);
  const std::string input = cl.positional()[0];
  if (Status s = CheckRange("eps-h", po.extraction.eps_h_px, 0.05, 100); !s.ok()) {
    return Fail("run", s.message(), 2);
  }
  if (Status s = CheckRange("refine-window", int64_t{po.refine.window_anchors}, 3, 30); !s.ok()) {
    return Fail("run", s.message(), 2);
  }
  auto scale = scale_flags.Options();
  if (!scale.ok()) return Fail("run", scale.status().message(), 2);
  po.scale = *scale;
  po.frame_poses.enabled = !anchors_only;

  std::optional<GroundTruth> gt;
  if (cl.Has("gt")) {
    auto loaded = LoadGroundTruth(gt_dir);
    if (!loaded.ok()) return Fail("run", "--gt: " + loaded.status().ToString(), 2);
    gt = std::move(*loaded);
  }
  ro.reencode = !no_reencode;
  auto reader = MvReader::Open(input, ro);
  if (!reader.ok()) return Fail("run", reader.status().ToString());
  const StreamInfo& info = (*reader)->info();
  auto intrinsics = IntrinsicsFor(intrinsics_spec, input, info.width_px, info.height_px);
  if (!intrinsics.ok()) return Fail("run", intrinsics.status().message(), 2);
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) return Fail("run", "cannot create " + out_dir + ": " + ec.message());

  CsvFile steps_csv(nullptr, &std::fclose);
  if (cl.Has("steps-csv")) {
    steps_csv = OpenStepsCsv(steps_csv_path);
    if (!steps_csv) return Fail("run", "cannot write " + steps_csv_path);
  }
  Pipeline pipeline(*intrinsics, info.mv_sigma_px(), po);
  std::vector<PlaneEstimate> plane_estimates;
  const bool progress = !quiet && isatty(STDERR_FILENO);
  PipelineStepCounts counts;
  std::string last_note;                       // why the last untracked step did not track
  std::string scale_note;                      // the last step's, when it said something
  std::map<PairMotionPath, int> motion_paths;  // PipelineStep::motion_path -> pairs
  auto record = [&](const PipelineStep& s) {
    if (!s.note.empty()) last_note = s.note;
    ++motion_paths[s.motion_path];
    if (!s.scale_note.empty()) scale_note = s.scale_note;
    if (steps_csv) WriteStepRow(steps_csv.get(), s, pipeline.trajectory());
    AppendPlaneEstimates(s.later_index, s.planes, s.extracted, s.extracted_filter_ids,
                         &plane_estimates);
  };
  FrameRecord frame;
  Status end;
  while ((end = (*reader)->Next(&frame)).ok()) {
    auto step = pipeline.Push(frame);
    if (!step.ok()) return Fail("run", step.status().ToString());
    if (progress && frame.index % 15 == 0) {
      std::fprintf(stderr, "\rframe %lld  t %.1f s  anchor pairs %d (tracking %d)  planes %zu   ",
                   static_cast<long long>(frame.index), frame.timestamp_s, counts.pairs,
                   counts.tracked, pipeline.plane_map().size());
    }
    if (step->has_value()) {
      counts.Add(**step);
      record(**step);
    }
  }
  // A pair still handed back at the end (its frames' poses): processed as it is.
  if (std::optional<PipelineStep> last = pipeline.Finish(); last.has_value()) {
    counts.AddFinish(*last);
    record(*last);
  }
  if (progress) std::fprintf(stderr, "\n");
  const bool stream_ok = end.code() == StatusCode::kOutOfRange;
  if (!stream_ok)
    std::fprintf(stderr, "slapse run: %s (results up to there)\n", end.ToString().c_str());

  if (Status s = WriteResults(pipeline, out_dir); !s.ok()) return Fail("run", s.ToString());
  // The stream's own codec (a re-encoded one's vectors come from info.codec_name).
  const std::string& codec = info.reencoded_from.empty() ? info.codec_name : info.reencoded_from;
  std::printf("input      %s (%s, %dx%d, %lld frames)\n", input.c_str(), codec.c_str(),
              info.width_px, info.height_px, static_cast<long long>((*reader)->stats().frames));
  PrintStreamReport(info, (*reader)->stats());
  std::printf(
      "tracked    %d of %d anchor pairs (%d extended), %zu anchor poses, %zu planes in "
      "the map (%s)\n",
      counts.tracked, counts.pairs, counts.extended, pipeline.trajectory().size(),
      pipeline.plane_map().size(), pipeline.metric() ? "metres" : "up to scale: first step = 1");
  std::map<PoseKind, int> kinds;
  for (const FramePose& p : pipeline.poses()) ++kinds[p.quality.kind];
  std::printf(
      "poses      %zu frames posed: %d anchor, %d coasting, %d motion-only, %d frame, %d "
      "interpolated\n",
      pipeline.poses().size(), kinds[PoseKind::kAnchor], kinds[PoseKind::kCoasting],
      kinds[PoseKind::kMotionOnly], kinds[PoseKind::kFrame], kinds[PoseKind::kInterpolated]);
  // Each pair's motion estimate, including a pair estimated again when it was
  // extended: the full fit is the pipeline's costliest stage.
  std::printf(
      "motion     %d pairs from the previous pair's motion, %d from a turn of it, %d by the "
      "full fit, %d with none (too few vectors, or the estimate failed)\n",
      motion_paths[PairMotionPath::kPrior], motion_paths[PairMotionPath::kTurnedPrior],
      motion_paths[PairMotionPath::kFullFit], motion_paths[PairMotionPath::kNone]);
  if (!scale_note.empty()) std::printf("scale      %s\n", scale_note.c_str());
  if (!pipeline.trajectory().empty()) {
    std::printf("support    %s\n", pipeline.scale_support().Summary().c_str());
  }

  if (pipeline.trajectory().empty()) {
    // Never a silent empty result: say why (a still camera, a stream too short or too small).
    std::printf("no poses   %s\n",
                counts.pairs == 0
                    ? "no anchor pair was closed (too few frames, or no two anchor frames)"
                    : ("none of the anchor pairs tracked; the last: " +
                       (last_note.empty() ? std::string("(no reason given)") : last_note))
                          .c_str());
  }
  MapAndErrors(pipeline, gt, plane_estimates, out_dir);
  std::printf(
      "wrote      %s/{trajectory_tum.txt, trajectory_kitti.txt, trajectory_quality.csv, "
      "planes.json, map.png}\n",
      out_dir.c_str());
  return stream_ok ? 0 : 1;
}

}  // namespace slapse::cli
