// motion_accuracy: per anchor pair, the rotation and translation-direction
// errors of the pair's motion (core/estimators/pair_motion.h) against a
// simulated drive's ground truth, for the full robust fit (no prior) and the
// seeded fast path (the previous pair's motion as prior: the pipeline's front
// end, core/pipeline/front_end.h, as `slapse run` computes it).
// With --pairs, a line per anchor pair: the full fit's has_motion tests
// (pair_motion.h) next to what the true motion gives for the same
// correspondences (true_in: within ransac_threshold_px (Sampson) of the true
// epipolar geometry; true_par: those of them off the true rotation by >=
// tau_inf_px), to tell bad MVs from a bad decision. --prior-scan-seeds N sets
// the fast path's PairMotionOptions::prior_scan_seeds (0: no scanned rotations).
//   build/bench/motion_accuracy [--pairs] [--prior-scan-seeds N] DRIVE_DIR [DRIVE_DIR ...]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "core/common/angles.h"
#include "core/common/so3.h"
#include "core/estimators/pair_motion.h"
#include "core/estimators/relative_pose.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/front_end.h"
#include "lab/gt/ground_truth.h"

namespace {

double AngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return slapse::RadToDeg(Eigen::AngleAxisd(a.transpose() * b).angle());
}

struct Acc {
  int n = 0, motion = 0, from_prior = 0, scanned = 0;
  double sq_rot = 0, sq_dir = 0;
  void Add(const slapse::PairMotionReport& r, const slapse::Rigid3d& truth) {
    ++n;
    if (!r.has_motion) return;
    ++motion;
    from_prior += r.motion_from_prior;
    scanned += r.prior_rotation_scanned;
    const double er = AngleDeg(r.later_from_earlier.R(), truth.R());
    const double et = slapse::AngleBetweenDeg(r.later_from_earlier.translation, truth.translation);
    sq_rot += er * er;
    sq_dir += et * et;
  }
  void Print(const char* name) const {
    std::printf(
        "  %-8s pairs %d, motion %d (from prior %d, of them from a scanned rotation %d): "
        "rotation RMSE %.4f deg, t direction RMSE %.3f deg\n",
        name, n, motion, from_prior, scanned, std::sqrt(sq_rot / std::max(1, motion)),
        std::sqrt(sq_dir / std::max(1, motion)));
  }
};

// The pair's correspondences against the true motion: *in within the
// threshold of the true epipolar geometry, *par of them with rotation-only
// parallax >= min_parallax_px under the true rotation (KRKinv = K R K^-1).
void CountAgainstTruth(const slapse::AnchorPair& pair, const slapse::Intrinsics& k,
                       const slapse::Rigid3d& truth, const Eigen::Matrix3d& KRKinv,
                       double threshold_px, double min_parallax_px, int* in, int* par) {
  *in = *par = 0;
  const double f = 0.5 * (k.fx_px + k.fy_px);
  const Eigen::Matrix3d E = slapse::Skew(truth.translation.normalized()) * truth.R();
  for (const slapse::Correspondence& c : pair.correspondences) {
    const double d = std::abs(
        slapse::SampsonDistance(E, k.Unproject(c.x_earlier_px), k.Unproject(c.x_later_px)));
    if (d * f > threshold_px) continue;
    ++*in;
    if (slapse::RotationOnlyParallaxPx(KRKinv, c) >= min_parallax_px) ++*par;
  }
}

// The road's (plane 0) correspondences: *n of them, *ok within 1 px of the
// true transfer, *ok_par of those with true rotation-only parallax >= tau_inf;
// *gain: the least-squares factor from the true flow to the decoded one over
// the *ok vectors (1: unbiased; < 1: the vectors are short).
void CountRoad(const slapse::AnchorPair& pair, const slapse::GroundTruth& gt,
               const Eigen::Matrix3d& KRKinv, double min_parallax_px, int* n, int* ok, int* ok_par,
               double* gain) {
  *n = *ok = *ok_par = 0;
  double dot = 0.0, sq = 0.0;
  for (const slapse::Correspondence& c : pair.correspondences) {
    if (gt.LabelAt(static_cast<int>(pair.later_index), c.x_later_px.x(), c.x_later_px.y()) != 0) {
      continue;
    }
    ++*n;
    Eigen::Vector2d x;
    if (!gt.TransferThroughPlane(0, static_cast<int>(pair.later_index),
                                 static_cast<int>(pair.earlier_index), c.x_later_px, &x)) {
      continue;
    }
    if ((x - c.x_earlier_px).norm() > 1.0) continue;
    ++*ok;
    const Eigen::Vector2d true_flow = c.x_later_px - x, flow = c.x_later_px - c.x_earlier_px;
    dot += true_flow.dot(flow);
    sq += true_flow.squaredNorm();
    if (slapse::RotationOnlyParallaxPx(KRKinv, c) >= min_parallax_px) ++*ok_par;
  }
  *gain = sq > 0.0 ? dot / sq : 0.0;
}

void PrintPair(const slapse::AnchorPair& pair, const slapse::PairMotionReport& r,
               const slapse::Rigid3d& truth, const slapse::GroundTruth& gt,
               const slapse::InfinityOptions& o) {
  const slapse::Intrinsics& k = gt.intrinsics;
  int true_in = 0, true_par = 0, road = 0, road_ok = 0, road_ok_par = 0;
  double road_gain = 0.0;
  const Eigen::Matrix3d KRKinv = k.K() * truth.R() * k.K().inverse();
  CountAgainstTruth(pair, k, truth, KRKinv, o.ransac_threshold_px, o.tau_inf_px, &true_in,
                    &true_par);
  CountRoad(pair, gt, KRKinv, o.tau_inf_px, &road, &road_ok, &road_ok_par, &road_gain);
  const double er = r.has_motion ? AngleDeg(r.later_from_earlier.R(), truth.R()) : -1;
  const double et =
      r.has_motion ? slapse::AngleBetweenDeg(r.later_from_earlier.translation, truth.translation)
                   : -1;
  std::printf(
      "  %lld-%lld n %zu motion %d e_in %d cheir %d rot_out %d par_in %d samp_in %d band %d | "
      "true_in %d true_par %d road %d ok %d ok_par %d gain %.3f |t| %.2f | err rot %.3f dir "
      "%.2f\n",
      static_cast<long long>(pair.earlier_index), static_cast<long long>(pair.later_index),
      pair.correspondences.size(), r.has_motion ? 1 : 0, r.num_e_inliers, r.num_cheirality_inliers,
      r.num_rotation_outliers, r.num_parallax_inliers, r.num_parallax_sampson_inliers,
      r.num_parallax_control_band, true_in, true_par, road, road_ok, road_ok_par, road_gain,
      truth.translation.norm(), er, et);
}

}  // namespace

int main(int argc, char** argv) {
  Acc all_full, all_seeded;
  bool pairs = false;
  int scan_seeds = slapse::PairMotionOptions().prior_scan_seeds;
  for (int a = 1; a < argc; ++a) {
    const std::string dir = argv[a];
    if (dir == "--pairs") {
      pairs = true;
      continue;
    }
    if (dir == "--prior-scan-seeds" && a + 1 < argc) {
      scan_seeds = std::atoi(argv[++a]);
      continue;
    }
    auto gt = slapse::LoadGroundTruth(dir);
    auto reader = slapse::MvReader::Open(dir + "/drive.ts");
    if (!gt.ok() || !reader.ok()) {
      std::fprintf(stderr, "cannot read %s\n", dir.c_str());
      return 1;
    }
    slapse::FrontEndOptions front_end_options;
    front_end_options.infinity.prior_scan_seeds = scan_seeds;
    slapse::FrontEnd front_end(gt->intrinsics, (*reader)->info().mv_sigma_px(), front_end_options);
    const slapse::InfinityOptions options;
    Acc full, seeded;
    slapse::FrameRecord frame;
    while ((*reader)->Next(&frame).ok()) {
      std::optional<slapse::FrontEndStep> step = front_end.Push(frame);
      if (!step.has_value()) continue;
      const slapse::AnchorPair& pair = step->pair;
      const slapse::Rigid3d truth = gt->frames[pair.later_index].world_from_cam.Inverse() *
                                    gt->frames[pair.earlier_index].world_from_cam;
      // The full fit: no prior.
      auto f = slapse::EstimatePairMotion(pair.correspondences, gt->intrinsics, options,
                                          options.tau_inf_px);
      const auto& s = step->infinity;
      if (!f.ok() || !s.ok()) continue;
      if (pairs) PrintPair(pair, *f, truth, *gt, options);
      full.Add(*f, truth);
      seeded.Add(*s, truth);
      all_full.Add(*f, truth);
      all_seeded.Add(*s, truth);
    }
    std::printf("%s\n", dir.c_str());
    full.Print("full");
    seeded.Print("seeded");
  }
  std::printf("all\n");
  all_full.Print("full");
  all_seeded.Print("seeded");
  return 0;
}
