// The relative motion of an anchor pair from its merged MB correspondences
// (paper Sec. V-B, which needs the rotation to threshold the plane at
// infinity; docs/METHOD.md "Pair motion and plane at infinity").
//
// Conventions.
//  - Pixels as in core/common/camera.h (pixel centres on integers).
//  - later_from_earlier = (R, t): X_later = R * X_earlier + t for a 3D point in
//    the two camera frames (Rigid3d's b_from_a). R "rotates C_k into C_{k+1}"
//    in the paper's words; the paper's K R^{-1} K^{-1} with R = earlier_from_later
//    rotation is the same map as K R K^{-1} here.
//  - Rotation-only prediction of the later pixel of correspondence i:
//      x'_later ~ K R K^{-1} [x_earlier; 1],
//    its distance to x_later (the MB centre) is the correspondence's parallax
//    in pixels (+infinity when x'_later is behind the camera).
//
// The estimate (EstimatePairMotion; details above each part in pair_motion.cc):
//  - full path: the essential matrix by USAC_MAGSAC with recoverPose's
//    cheirality (CountCheirality) (the motion then polished by RefineRelativePose, as the fast
//    path's), and a rotation-only model by our Ransac<>; translation counts
//    as observed (has_motion) only when enough E-inliers carry parallax that
//    the rotation-only model cannot explain, else the rotation-only model (or
//    the identity) is the motion;
//  - seeded fast path: the previous pair's motion refined locally, accepted
//    only when it decides has_motion clearly; when refused, a few rotations
//    near the prior's (a scan of yaw and pitch) are tried the same way;
//    otherwise the full path.
//
// Correspondences that are no E-inliers (wrong MVs) are not removed here:
// e_inlier_mask lets callers drop them.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "core/common/camera.h"
#include "core/common/rigid3.h"
#include "core/common/status.h"
#include "core/merge/correspondence.h"

namespace slapse {

struct PairMotionOptions {
  double ransac_threshold_px = 1.0;  // E and rotation-only RANSAC inlier threshold
  double confidence = 0.999;         // RANSAC confidence for both fits
  int min_correspondences = 15;      // fewer: no motion estimate (has_motion = false)
  // Translation needs this share of the rotation-only outliers to be E-inliers
  // (test (c) of the full path) ...
  double min_parallax_inlier_ratio = 0.25;
  // ... or (c') this many times as many parallax E-inliers as wrong MVs give
  // by chance, estimated from the rotation-only outliers in a control band of
  // Sampson distances (see FullPath). 0 = off (test (c) alone).
  double min_parallax_chance_ratio = 4.0;
  // Seeded fast path (see EstimatePairMotion): used when a prior is passed and this is set.
  bool use_prior = true;
  // The refined motion's Sampson-inlier share must reach this fraction of the
  // prior's reference_inlier_ratio (the last full fit's share).
  double prior_min_inlier_ratio = 0.9;
  // The fast path's has_motion tests must pass by this factor (>= 1).
  double prior_decision_margin = 1.5;
  // A refused prior is tried again from up to prior_scan_seeds other
  // rotations before the full path (0 = off): the prior's rotation turned
  // about the later camera's y axis (yaw, for a camera looking along the
  // road) by up to +-prior_scan_yaw_deg and about its x axis (pitch) by up to
  // +-prior_scan_pitch_deg, in steps of prior_scan_step_deg; the turns that
  // fit the most correspondences with the prior's translation go first. For
  // turns at low frame rates, where the rotation changes by degrees from one
  // pair to the next and the refinement's reach is about one degree
  // (docs/METHOD.md "Pair motion and plane at infinity").
  int prior_scan_seeds = 3;
  double prior_scan_yaw_deg = 6.0;
  double prior_scan_pitch_deg = 2.0;
  double prior_scan_step_deg = 0.5;

  // InvalidArgument (prefixed with `who`) unless ransac_threshold_px > 0,
  // confidence in (0, 1), min_parallax_inlier_ratio in [0, 1],
  // min_parallax_chance_ratio >= 0,
  // prior_min_inlier_ratio >= 0, prior_decision_margin >= 1,
  // prior_scan_seeds >= 0, prior_scan_yaw_deg and prior_scan_pitch_deg in
  // [0, 30] and prior_scan_step_deg >= 0.1 (at most 601 x 601 turns).
  Status Check(const std::string& who = "PairMotionOptions") const;
};

// A guess of the pair's motion for the seeded fast path.
struct PairMotionPrior {
  // X_later = R X_earlier + t, |t| > 0 (up to scale): e.g. the previous anchor
  // pair's later_from_earlier.
  Rigid3d later_from_earlier;
  // Share of the correspondences that were Sampson inliers of the last full
  // (USAC_MAGSAC) fit: its num_sampson_inliers / correspondences.
  double reference_inlier_ratio = 0.0;
};

enum class PairRotationSource {
  kEssential,     // R from E + cheirality (has_motion = true)
  kRotationOnly,  // R from the rotation-only fit (pure rotation / no translation)
  kIdentity,      // nothing could be estimated: R = I
};

struct PairMotionReport {
  bool has_motion = false;
  PairRotationSource rotation_source = PairRotationSource::kIdentity;
  // X_later = R X_earlier + t; |t| = 1 when has_motion, t = 0 otherwise.
  Rigid3d later_from_earlier;
  // later_from_earlier's rotation as the estimator produced it (identity when
  // nothing was estimated). Rigid3d holds a quaternion, whose matrix differs
  // in the last bits; the plane-at-infinity threshold uses this one.
  Eigen::Matrix3d R_later_from_earlier = Eigen::Matrix3d::Identity();
  std::vector<char> e_inlier_mask;  // per correspondence; all 0 when E was not estimated
  int num_e_inliers = 0;
  int num_cheirality_inliers = 0;  // E-inliers in front of both cameras (CountCheirality)
  int num_rotation_outliers = 0;   // points off the rotation-only model by >= min parallax
  int num_parallax_inliers = 0;    // ... of which E-inliers
  // Full path with an E: rotation-only outliers within ransac_threshold_px
  // (Sampson) of it, and those in the control band (2, 6] x ransac_threshold_px.
  int num_parallax_sampson_inliers = 0;
  int num_parallax_control_band = 0;
  // has_motion only: correspondences whose Sampson distance under
  // later_from_earlier is <= ransac_threshold_px (in px via the mean focal length).
  int num_sampson_inliers = 0;
  bool motion_from_prior = false;  // the seeded fast path was accepted
  // ... from a scanned rotation (prior_scan_seeds), not the prior's own.
  bool prior_rotation_scanned = false;
  // The full path ran (USAC_MAGSAC and the rotation-only RANSAC: the costly
  // one, docs/BENCHMARKS.md "Session 31"). False on the fast path and when
  // there were too few correspondences to estimate anything.
  bool full_fit = false;
  // Full path: the rotation-only model was polished from E's rotation (no
  // random search; see FullPath in pair_motion.cc).
  bool rotation_only_from_essential = false;
};

// How a pair's motion was found, for reports.
enum class PairMotionPath {
  kNone,         // too few correspondences: nothing was estimated
  kPrior,        // the fast path from the prior's rotation
  kTurnedPrior,  // the fast path from a scanned rotation (prior_scan_seeds)
  kFullFit,      // the full path
};
PairMotionPath PairMotionPathOf(const PairMotionReport& report);
// "none", "prior", "turned prior", "full fit".
const char* PairMotionPathName(PairMotionPath path);

// The pair's motion: the seeded fast path when `prior` is given and
// options.use_prior, else (or when the prior is refused) the full path.
// min_parallax_px: a correspondence off the rotation-only model by at least
// max(min_parallax_px, ransac_threshold_px) carries parallax (tests (b) and
// (c) of the full path); the plane-at-infinity threshold passes its tau_inf_px.
// InvalidArgument: intrinsics failing ValidateIntrinsics (core/common/camera.h),
// non-finite correspondence coordinates, or options failing Check().
// Internal: OpenCV threw (not expected for finite input).
// prior: a guess of the motion for the seeded fast path (null: full path only).
StatusOr<PairMotionReport> EstimatePairMotion(const std::vector<Correspondence>& correspondences,
                                              const Intrinsics& intrinsics,
                                              const PairMotionOptions& options,
                                              double min_parallax_px,
                                              const PairMotionPrior* prior = nullptr);

// ||dehom(K R K^{-1} x_earlier) - x_later|| in pixels for KRKinv = K R K^{-1};
// +infinity behind the camera.
double RotationOnlyParallaxPx(const Eigen::Matrix3d& KRKinv, const Correspondence& c);

// Carries the motion from one anchor pair to the next for the seeded fast
// path: the prior for a pair is the previous pair's motion when that pair had
// one and ended where this one starts; its reference_inlier_ratio is the last
// full fit's Sampson-inlier share (kept through a run of seeded fits, so they
// cannot drift it down). A fit from a scanned rotation sets a new reference,
// as the full fit it stands in for would have.
class PairMotionPriorTracker {
 public:
  // Null when there is no usable prior for `pair`.
  const PairMotionPrior* PriorFor(const AnchorPair& pair) const;
  // Records the pair's result (null: the estimation failed), whose
  // PriorFor(pair) must have been the prior it ran with.
  void Record(const AnchorPair& pair, const PairMotionReport* result);
  void Reset();

 private:
  std::optional<PairMotionPrior> prior_;
  int64_t later_index_ = -1;  // the later anchor of the pair prior_ came from
};

}  // namespace slapse
