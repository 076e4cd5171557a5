// slapse planes: extract planes from a stream's motion vectors and draw one
// anchor pair's planes as coloured macroblock dots (the paper's Fig. 5).
// slapse eval-planes: the paper's Table I on simulated drives.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "core/common/intrinsics_io.h"
#include "core/merge/mv_merge.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/front_end.h"
#include "core/planes/infinity.h"
#include "core/planes/plane_extraction.h"
#include "core/viz/plane_overlay.h"
#include "lab/eval/extraction_eval.h"
#include "lab/sim/simulate.h"

namespace slapse::cli {
namespace {

StatusOr<std::vector<double>> ParseList(const std::string& text, const std::string& name) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0') {
      return InvalidArgumentError("--" + name + " must be a comma-separated list, got '" + text +
                                  "'");
    }
    out.push_back(v);
  }
  if (out.empty()) return InvalidArgumentError("--" + name + " is empty");
  return out;
}

using CsvFile = std::unique_ptr<std::FILE, int (*)(std::FILE*)>;

// --planes-csv with its header, or null if it cannot be written.
CsvFile OpenPlanesCsv(const std::string& path) {
  CsvFile csv(std::fopen(path.c_str(), "w"), &std::fclose);
  if (csv) {
    std::fprintf(csv.get(),
                 "drive,later_index,track_id,tracked,mbs,mean_mb_row,gt_plane,gt_kind,purity,"
                 "mixed_share,transfer_px,true_positive,rms_transfer_px,track_change,"
                 "mean_imvs,e_inlier_share,median_parallax_px,hole_share,boundary_share,"
                 "fill_share,bbox_fill,near2,near3,back_fit,back_fit15,normal_down,"
                 "motion_rot_err_deg,motion_dir_err_deg,vertical_err_deg,normal_true_down,"
                 "normal_learnt_down\n");
  }
  return csv;
}

// The directories of the drives `drive` with these seeds under `dir`,
// simulated unless they exist already.
StatusOr<std::vector<std::string>> SimulatedDrives(const SimulateOptions& drive,
                                                   const std::vector<double>& seeds,
                                                   const std::string& dir) {
  std::vector<std::string> dirs;
  for (double seed : seeds) {
    SimulateOptions opt = drive;
    opt.seed = static_cast<uint64_t>(seed);
    opt.output_dir = dir + "/seed" + std::to_string(opt.seed);
    if (!std::filesystem::exists(opt.output_dir + "/meta.json")) {
      std::fprintf(stderr, "simulating %s ...\n", opt.output_dir.c_str());
      SimulateReport rep;
      SLAPSE_RETURN_IF_ERROR(SimulateDrive(opt, &rep));
    }
    dirs.push_back(opt.output_dir);
  }
  return dirs;
}

}  // namespace

int RunPlanes(int argc, char** argv) {
  CommandLine cl("planes", "INPUT --frame N [options]", "INPUT");
  CLI::App& app = cl.app();
  int64_t frame_index = 0;
  std::string png = "planes.png", intrinsics_spec;
  PlaneExtractionOptions po;
  InfinityOptions io;
  app.add_option("--frame", frame_index,
                 "draw the anchor pair whose later anchor is the first at or after N")
      ->type_name("N");
  app.add_option("--png", png, "picture to write")->type_name("FILE")->capture_default_str();
  app.add_option("--eps-h", po.eps_h_px, "homography inlier threshold")
      ->type_name("PX")
      ->capture_default_str();
  app.add_option("--tau-inf", io.tau_inf_px, "plane-at-infinity parallax threshold")
      ->type_name("PX")
      ->capture_default_str();
  app.add_option("--intrinsics", intrinsics_spec,
                 "FILE.json, 'fx,fy,cx,cy' or 'hfov=DEG' (default: intrinsics.json beside INPUT)")
      ->type_name("SPEC");
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  if (cl.positional().size() != 1) return Fail("planes", "expected one INPUT (see --help)", 2);
  if (!cl.Has("frame")) return Fail("planes", "--frame N is required", 2);
  for (const Status& s : {CheckRange("frame", frame_index, int64_t{0}, INT64_MAX),
                          CheckRange("eps-h", po.eps_h_px, 0.05, 100),
                          CheckRange("tau-inf", io.tau_inf_px, 0, 100)}) {
    if (!s.ok()) return Fail("planes", s.message(), 2);
  }
  const std::string input = cl.positional()[0];
  MvReaderOptions ro;
  ro.keep_luma = true;
  auto reader = MvReader::Open(input, ro);
  if (!reader.ok()) return Fail("planes", reader.status().ToString());
  const StreamInfo& info = (*reader)->info();
  auto intrinsics = IntrinsicsFor(intrinsics_spec, input, info.width_px, info.height_px);
  if (!intrinsics.ok()) return Fail("planes", intrinsics.status().message(), 2);

  // The pipeline's front end, as `run` computes it (motion prior included); a
  // pair whose motion or extraction fails has no planes, as in `run`.
  FrontEndOptions fo;
  fo.extraction = po;
  fo.infinity = io;
  FrontEnd front_end(*intrinsics, info.mv_sigma_px(), fo);
  FrameRecord f;
  Status end;
  while ((end = (*reader)->Next(&f)).ok()) {
    std::optional<FrontEndStep> step = front_end.Push(f);
    if (!step.has_value() || step->pair.later_index < frame_index) continue;
    const AnchorPair& pair = step->pair;
    const std::vector<ExtractedPlane> planes =
        step->extraction.ok() ? step->extraction->planes : std::vector<ExtractedPlane>();
    const cv::Mat picture = DrawPlanes(f.luma, info.width_px, info.height_px, pair.earlier_index,
                                       pair.later_index, planes);
    if (!cv::imwrite(png, picture)) {
      return Fail("planes", "cannot write " + png);
    }
    std::printf(
        "anchors %lld -> %lld (%s): %zu correspondences, %zu with parallax, %zu planes\n",
        static_cast<long long>(pair.earlier_index), static_cast<long long>(pair.later_index),
        SegmentTypeName(pair.type), pair.correspondences.size(),
        step->infinity.ok() ? step->infinity->kept_indices.size() : size_t{0}, planes.size());
    for (const Status* s : {&step->infinity.status(), &step->extraction.status()}) {
      if (!s->ok()) std::printf("  no planes: %s\n", s->ToString().c_str());
    }
    for (const ExtractedPlane& p : planes) {
      std::printf("  plane %d: %zu MBs%s\n", p.track_id, p.mb_indices.size(),
                  p.tracked ? " (tracked)" : " (new)");
    }
    std::printf("picture    %s\n", png.c_str());
    return 0;
  }
  if (end.code() != StatusCode::kOutOfRange) return Fail("planes", end.ToString());
  return Fail("planes", "the stream has no anchor pair ending at or after frame " +
                            std::to_string(frame_index));
}

int RunEvalPlanes(int argc, char** argv) {
  CommandLine cl("eval-planes", "[options]");
  CLI::App& app = cl.app();
  std::string seeds_text = "1,2,3,4,5", eps_text = "1,2,3,4", dir = "out/eval-planes", csv_path;
  SimulateOptions drive;  // the drives' length only; the rest as SimulateOptions{}
  ExtractionEvalOptions eo;
  app.add_option("--seeds", seeds_text, "simulated drives to evaluate")
      ->type_name("LIST")
      ->capture_default_str();
  app.add_option("--eps-h", eps_text, "homography thresholds to sweep, px")
      ->type_name("LIST")
      ->capture_default_str();
  app.add_option("--dir", dir, "where the drives are simulated (reused if present)")
      ->type_name("DIR")
      ->capture_default_str();
  app.add_option("--duration-s", drive.duration_s, "length of each drive")
      ->type_name("S")
      ->capture_default_str();
  app.add_option("--tau-inf", eo.infinity.tau_inf_px, "plane-at-infinity threshold, px")
      ->type_name("PX")
      ->capture_default_str();
  bool free_homography = false;
  app.add_flag("--free-homography", free_homography,
               "fit free 8-parameter homographies (the paper's way), not ones "
               "consistent with the pair's motion");
  app.add_option("--planes-csv", csv_path, "also write one CSV row per extracted plane (scores)")
      ->type_name("FILE");
  app.add_option("--boundary-frac", eo.extraction.boundary_residual_frac,
                 "drop border blocks with transfer error > F * eps_h (< 0: off; see "
                 "PlaneExtractionOptions)")
      ->type_name("F")
      ->capture_default_str();
  app.add_flag("--boundary-ignore-empty", eo.extraction.boundary_ignore_empty,
               "with --boundary-frac: cells without MVs do not make a block a border block");
  app.add_flag("--drop-e-outliers", eo.extraction.drop_e_outliers,
               "fit planes to the essential matrix's inliers only");
  app.add_option("--facade-tilt-deg", eo.extraction.max_facade_tilt_deg,
                 "street-scene prior: largest tilt of a wall's normal from horizontal (negative: "
                 "prior off)")
      ->type_name("DEG")
      ->capture_default_str();
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  eo.extraction.use_motion = !free_homography;
  auto seeds = ParseList(seeds_text, "seeds");
  auto eps_list = ParseList(eps_text, "eps-h");
  for (const Status& s :
       {seeds.status(), eps_list.status(), CheckRange("duration-s", drive.duration_s, 1, 600),
        CheckRange("tau-inf", eo.infinity.tau_inf_px, 0, 100),
        CheckRange("boundary-frac", eo.extraction.boundary_residual_frac, -1, 10),
        CheckRange("facade-tilt-deg", eo.extraction.max_facade_tilt_deg, -1, 90)}) {
    if (!s.ok()) return Fail("eval-planes", s.message(), 2);
  }
  CsvFile csv(nullptr, &std::fclose);
  if (cl.Has("planes-csv")) {
    csv = OpenPlanesCsv(csv_path);
    if (!csv) return Fail("eval-planes", "cannot write " + csv_path);
  }
  auto dirs = SimulatedDrives(drive, *seeds, dir);
  if (!dirs.ok()) return Fail("eval-planes", dirs.status().ToString());
  std::printf(
      "| eps_h (px) | anchor pairs | planes extracted | TP rate | recall (all visible) | "
      "recall (road + facades) | recall (>= 20 kept MBs) |\n"
      "|---:|---:|---:|---:|---:|---:|---:|\n");
  ExtractionStats last;
  for (double eps : *eps_list) {
    eo.extraction.eps_h_px = eps;
    eo.planes_csv = csv.get();
    ExtractionStats total;
    for (const std::string& drive_dir : *dirs) {
      auto stats = EvaluateExtraction(drive_dir, eo);
      if (!stats.ok()) return Fail("eval-planes", drive_dir + ": " + stats.status().ToString());
      total.Add(*stats);
    }
    std::printf("| %.1f | %d | %d | %.1f %% | %.1f %% | %.1f %% | %.1f %% |\n", eps, total.pairs,
                total.planes, 100 * total.tp_rate(), 100 * total.recall(),
                100 * total.recall_near(), 100 * total.recall_kept());
    last = total;
  }
  if (last.pairs > 0) {
    std::printf(
        "\nstage time per anchor pair (last row): merging %.2f ms, thresholding %.2f ms, "
        "plane fitting %.2f ms\n",
        last.merge_ms / last.pairs, last.threshold_ms / last.pairs, last.fit_ms / last.pairs);
  }
  return 0;
}

}  // namespace slapse::cli
