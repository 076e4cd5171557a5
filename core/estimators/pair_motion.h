// The relative motion of an anchor pair from its merged MB correspondences
// (paper Sec. V-B, which needs the rotation to threshold the plane at
// infinity; docs/METHOD.md "Pair motion").
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
// Full path (EstimatePairMotion without a prior, or when the prior is refused).
//   cv::findEssentialMat(x_earlier, x_later, K, cv::USAC_MAGSAC, confidence,
//   ransac_threshold_px) and cv::recoverPose (cheirality), which give
//   later_from_earlier with |t| = 1. Pixels go in directly with K; OpenCV turns
//   the threshold into normalised units by the mean focal length. USAC_MAGSAC,
//   not cv::RANSAC: the latter returns a minimal-sample E, whose R is off by
//   ~0.1 deg on the synthetic street (0.25 px noise) -- 0.8 px of fake parallax
//   at f = 457 px, which alone pushes far points over tau_inf = 1 px. MAGSAC's
//   polished E gives ~0.01-0.02 deg. OpenCV's USAC seeds its RNG with a fixed
//   state, so the result is deterministic.
//
// Degenerate epipolar geometry (has_motion = false, no error). With no or too
// little translation, E is undetermined (every t fits a pure rotation), and the
// R from recoverPose may be the wrong member of the twisted pair. So a
// rotation-only model is fitted as well: our Ransac<> over 2-point Kabsch fits
// on the bearing vectors, with the residual in pixels approximated as the mean
// focal length times the normalised-image-plane error. Translation counts as
// observed iff (a) cheirality holds for >= min_correspondences points, (b) at
// least min_correspondences E-inliers deviate from that rotation-only model by
// >= max(min_parallax_px, ransac_threshold_px) (parallax that E explains), and
// (c) those are at least min_parallax_inlier_ratio of all points the
// rotation-only model does not explain. (c) matters: under a pure rotation E is
// free to pick the t that makes the most *wrong* MVs look epipolar-consistent;
// with half the MVs wrong (+-32 px) that is 20-30 points with cheirality --
// above any sensible absolute count -- but < 10% of them, while genuine
// parallax points are almost all E-inliers. Otherwise has_motion = false,
// later_from_earlier = (R_rotation_only, 0) -- or the identity when even that
// fit fails or there are fewer than max(min_correspondences, 5) correspondences
// (then nothing is estimated).
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
  // Translation needs this share of the rotation-only outliers to be E-inliers.
  double min_parallax_inlier_ratio = 0.25;
  // Seeded fast path (see EstimatePairMotion): used when a prior is passed and this is set.
  bool use_prior = true;
  // The refined motion's Sampson-inlier share must reach this fraction of the
  // prior's reference_inlier_ratio (the last full fit's share).
  double prior_min_inlier_ratio = 0.9;
  // The fast path's has_motion tests must pass by this factor (>= 1).
  double prior_decision_margin = 1.5;

  // InvalidArgument (prefixed with `who`) unless ransac_threshold_px > 0,
  // confidence in (0, 1), min_parallax_inlier_ratio in [0, 1],
  // prior_min_inlier_ratio >= 0 and prior_decision_margin >= 1.
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
  int num_cheirality_inliers = 0;  // points recoverPose triangulated in front of both cameras
  int num_rotation_outliers = 0;   // points off the rotation-only model by >= min parallax
  int num_parallax_inliers = 0;    // ... of which E-inliers
  // has_motion only: correspondences whose Sampson distance under
  // later_from_earlier is <= ransac_threshold_px (in px via the mean focal length).
  int num_sampson_inliers = 0;
  bool motion_from_prior = false;  // the seeded fast path was accepted
};

// Seeded fast path (a prior given and options.use_prior). The motion of
// consecutive anchor pairs changes slowly, so the previous pair's motion is a
// good start: RefineRelativePose (core/estimators/relative_pose.h:
// Levenberg-Marquardt on the Sampson distance over R and t on the unit sphere,
// with LO-style inlier re-selection at 3, 2, 1.5, 1 x ransac_threshold_px)
// refines it, and the rotation-only model is polished (LO, no random search)
// from the refined R and the prior's R instead of a full RANSAC. The result is
// accepted only if
//  - its Sampson-inlier share (|r| f_mean <= ransac_threshold_px) is at least
//    prior_min_inlier_ratio x the prior's reference_inlier_ratio (the share of
//    the last full fit, so a refinement stuck in a worse local optimum is
//    caught), and
//  - it decides has_motion = true with a margin: (a) and (b) of the file
//    comment with prior_decision_margin x min_correspondences, (c) with
//    prior_decision_margin x min_parallax_inlier_ratio, and cheirality for at
//    least half the E-inliers.
// Otherwise everything is recomputed by the full path (USAC_MAGSAC, the
// rotation-only RANSAC): the fast path never decides "no motion", so the
// degenerate cases keep the full logic. With the fast path, e_inlier_mask holds
// the Sampson inliers of the refined motion and num_cheirality_inliers comes
// from CountCheirality (recoverPose's test, own triangulation).
//
// min_parallax_px: a correspondence off the rotation-only model by at least
// max(min_parallax_px, ransac_threshold_px) carries parallax (tests (b), (c));
// the plane-at-infinity threshold passes its tau_inf_px.
// InvalidArgument: intrinsics without positive finite focal lengths or a
// finite principal point, non-finite correspondence coordinates, or options
// failing Check(). Internal: OpenCV threw (not expected for finite input).
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
// cannot drift it down).
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
