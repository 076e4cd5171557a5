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
#include "core/eval/extraction_eval.h"
#include "core/merge/mv_merge.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/front_end.h"
#include "core/planes/infinity.h"
#include "core/planes/plane_extraction.h"
#include "core/sim/simulate.h"
#include "core/viz/plane_overlay.h"

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

}  // namespace

int RunPlanes(int argc, char** argv) {
  Flags flags(
      "planes", "INPUT --frame N [options]",
      {{"frame", "N", "draw the anchor pair whose later anchor is the first at or after N", ""},
       {"png", "FILE", "picture to write", "planes.png"},
       {"eps-h", "PX", "homography inlier threshold", "1"},
       {"tau-inf", "PX", "plane-at-infinity parallax threshold",
        std::to_string(static_cast<int>(InfinityOptions{}.tau_inf_px))},
       {"intrinsics", "SPEC",
        "FILE.json, 'fx,fy,cx,cy' or 'hfov=DEG' (default: intrinsics.json beside INPUT)", ""}});
  if (Status s = flags.Parse(argc, argv); !s.ok()) return Fail("planes", s.message(), 2);
  if (flags.help_requested()) {
    std::printf("%s", flags.Usage().c_str());
    return 0;
  }
  if (flags.positional().size() != 1) return Fail("planes", "expected one INPUT (see --help)", 2);
  if (!flags.Has("frame")) return Fail("planes", "--frame N is required", 2);
  auto frame_index = flags.GetInt("frame", 0, INT64_MAX);
  auto eps = flags.GetDouble("eps-h", 0.05, 100);
  auto tau = flags.GetDouble("tau-inf", 0, 100);
  for (const Status* s : {&frame_index.status(), &eps.status(), &tau.status()}) {
    if (!s->ok()) return Fail("planes", s->message(), 2);
  }
  const std::string input = flags.positional()[0];
  MvReaderOptions ro;
  ro.keep_luma = true;
  auto reader = MvReader::Open(input, ro);
  if (!reader.ok()) return Fail("planes", reader.status().ToString());
  const StreamInfo& info = (*reader)->info();
  auto intrinsics =
      IntrinsicsFor(flags.GetString("intrinsics"), input, info.width_px, info.height_px);
  if (!intrinsics.ok()) return Fail("planes", intrinsics.status().message(), 2);

  // The pipeline's front end, as `run` computes it (motion prior included); a
  // pair whose motion or extraction fails has no planes, as in `run`.
  FrontEndOptions fo;
  fo.extraction.eps_h_px = *eps;
  fo.infinity.tau_inf_px = *tau;
  FrontEnd front_end(*intrinsics, info.mv_sigma_px(), fo);
  FrameRecord f;
  Status end;
  while ((end = (*reader)->Next(&f)).ok()) {
    std::optional<FrontEndStep> step = front_end.Push(f);
    if (!step.has_value() || step->pair.later_index < *frame_index) continue;
    const AnchorPair& pair = step->pair;
    const std::vector<ExtractedPlane> planes =
        step->extraction.ok() ? step->extraction->planes : std::vector<ExtractedPlane>();
    const cv::Mat picture = DrawPlanes(f.luma, info.width_px, info.height_px, pair, planes);
    if (!cv::imwrite(flags.GetString("png"), picture)) {
      return Fail("planes", "cannot write " + flags.GetString("png"));
    }
    std::printf("anchors %lld -> %lld (%s): %zu correspondences, %zu with parallax, %zu planes\n",
                static_cast<long long>(pair.earlier_index),
                static_cast<long long>(pair.later_index), SegmentTypeName(pair.type),
                pair.correspondences.size(),
                step->infinity.ok() ? step->infinity->kept_indices.size() : size_t{0},
                planes.size());
    for (const Status* s : {&step->infinity.status(), &step->extraction.status()}) {
      if (!s->ok()) std::printf("  no planes: %s\n", s->ToString().c_str());
    }
    for (const ExtractedPlane& p : planes) {
      std::printf("  plane %d: %zu MBs%s\n", p.track_id, p.mb_indices.size(),
                  p.tracked ? " (tracked)" : " (new)");
    }
    std::printf("picture    %s\n", flags.GetString("png").c_str());
    return 0;
  }
  if (end.code() != StatusCode::kOutOfRange) return Fail("planes", end.ToString());
  return Fail("planes", "the stream has no anchor pair ending at or after frame " +
                            std::to_string(*frame_index));
}

int RunEvalPlanes(int argc, char** argv) {
  Flags flags(
      "eval-planes", "[options]",
      {{"seeds", "LIST", "simulated drives to evaluate", "1,2,3,4,5"},
       {"eps-h", "LIST", "homography thresholds to sweep, px", "1,2,3,4"},
       {"dir", "DIR", "where the drives are simulated (reused if present)", "out/eval-planes"},
       {"duration-s", "S", "length of each drive", "10"},
       {"tau-inf", "PX", "plane-at-infinity threshold, px",
        std::to_string(static_cast<int>(InfinityOptions{}.tau_inf_px))},
       {"free-homography", "",
        "fit free 8-parameter homographies (the paper's way), not ones "
        "consistent with the pair's motion",
        ""},
       {"planes-csv", "FILE", "also write one CSV row per extracted plane (scores)", ""},
       {"boundary-frac", "F",
        "drop border blocks with transfer error > F * eps_h (< 0: off; see "
        "PlaneExtractionOptions)",
        std::to_string(PlaneExtractionOptions{}.boundary_residual_frac)},
       {"boundary-ignore-empty", "",
        "with --boundary-frac: cells without MVs do not make a block a border block", ""},
       {"drop-e-outliers", "", "fit planes to the essential matrix's inliers only", ""},
       {"facade-tilt-deg", "DEG",
        "street-scene prior: largest tilt of a wall's normal from horizontal (negative: "
        "prior off)",
        std::to_string(PlaneExtractionOptions{}.max_facade_tilt_deg)}});
  if (Status s = flags.Parse(argc, argv); !s.ok()) return Fail("eval-planes", s.message(), 2);
  if (flags.help_requested()) {
    std::printf("%s", flags.Usage().c_str());
    return 0;
  }
  auto seeds = ParseList(flags.GetString("seeds"), "seeds");
  auto eps_list = ParseList(flags.GetString("eps-h"), "eps-h");
  auto duration = flags.GetDouble("duration-s", 1, 600);
  auto tau = flags.GetDouble("tau-inf", 0, 100);
  auto boundary_frac = flags.GetDouble("boundary-frac", -1, 10);
  auto facade_tilt = flags.GetDouble("facade-tilt-deg", -1, 90);
  for (const Status* s : {&seeds.status(), &eps_list.status(), &duration.status(), &tau.status(),
                          &boundary_frac.status(), &facade_tilt.status()}) {
    if (!s->ok()) return Fail("eval-planes", s->message(), 2);
  }
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> csv(nullptr, &std::fclose);
  if (flags.Has("planes-csv")) {
    csv.reset(std::fopen(flags.GetString("planes-csv").c_str(), "w"));
    if (!csv) return Fail("eval-planes", "cannot write " + flags.GetString("planes-csv"));
    std::fprintf(csv.get(),
                 "drive,later_index,track_id,tracked,mbs,mean_mb_row,gt_plane,gt_kind,purity,"
                 "mixed_share,transfer_px,true_positive,rms_transfer_px,track_change,"
                 "mean_imvs,e_inlier_share,median_parallax_px,hole_share,boundary_share,"
                 "fill_share,bbox_fill,near2,near3,back_fit,back_fit15,normal_down,"
                 "motion_rot_err_deg,motion_dir_err_deg,vertical_err_deg,normal_true_down,"
                 "normal_learnt_down\n");
  }
  std::vector<std::string> dirs;
  for (double seed : *seeds) {
    SimulateOptions opt;
    opt.seed = static_cast<uint64_t>(seed);
    opt.duration_s = *duration;
    opt.output_dir = flags.GetString("dir") + "/seed" + std::to_string(opt.seed);
    if (!std::filesystem::exists(opt.output_dir + "/meta.json")) {
      std::fprintf(stderr, "simulating %s ...\n", opt.output_dir.c_str());
      SimulateReport rep;
      if (Status s = SimulateDrive(opt, &rep); !s.ok()) return Fail("eval-planes", s.ToString());
    }
    dirs.push_back(opt.output_dir);
  }
  std::printf(
      "| eps_h (px) | anchor pairs | planes extracted | TP rate | recall (all visible) | "
      "recall (road + facades) | recall (>= 20 kept MBs) |\n"
      "|---:|---:|---:|---:|---:|---:|---:|\n");
  ExtractionStats last;
  for (double eps : *eps_list) {
    ExtractionEvalOptions eo;
    eo.extraction.eps_h_px = eps;
    eo.extraction.use_motion = !flags.Has("free-homography");
    eo.infinity.tau_inf_px = *tau;
    eo.extraction.boundary_residual_frac = *boundary_frac;
    eo.extraction.max_facade_tilt_deg = *facade_tilt;
    if (flags.Has("drop-e-outliers")) eo.extraction.drop_e_outliers = true;
    if (flags.Has("boundary-ignore-empty")) eo.extraction.boundary_ignore_empty = true;
    eo.planes_csv = csv.get();
    ExtractionStats total;
    for (const std::string& dir : dirs) {
      auto stats = EvaluateExtraction(dir, eo);
      if (!stats.ok()) return Fail("eval-planes", dir + ": " + stats.status().ToString());
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
