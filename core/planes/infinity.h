// Plane-at-infinity thresholding (paper Sec. V-B; docs/METHOD.md "Pair motion
// and plane at infinity"): drop the correspondences whose motion is explained
// by the camera rotation alone.
//
// Given the pair's motion (core/estimators/pair_motion.h: its rotation R,
// later_from_earlier, from the essential matrix or the rotation-only fit),
// each correspondence's rotation-only prediction of its later pixel is
//   x'_later ~ K R K^{-1} [x_earlier; 1],
// parallax_px[i] = ||x'_later - x_later|| (the MB centre), +infinity when
// x'_later is behind the camera (third coordinate <= 0). A correspondence is
// on the plane at infinity (dropped) iff parallax_px < tau_inf_px.
//
// Correspondences that are no E-inliers (wrong MVs) are thresholded like all
// others, as in the paper: they usually have large parallax, are kept, and are
// rejected later by the homography RANSAC. e_inlier_mask lets callers drop them.
#pragma once

#include <vector>

#include "core/common/camera.h"
#include "core/common/status.h"
#include "core/estimators/pair_motion.h"
#include "core/merge/correspondence.h"

namespace slapse {

// The motion's options (PairMotionOptions, whose parallax test uses tau_inf_px
// too) and the threshold.
struct InfinityOptions : PairMotionOptions {
  // Parallax below this: plane at infinity. The paper's 1 px keeps points with
  // a few px of parallax (distant facades, the end of the street near the
  // focus of expansion) that fit the homography of almost any near plane
  // within eps_h, so plane consensus sets collected them. 6 px (chosen on the
  // simulated drives, docs/PLANE_EXTRACTION.md: with the connectivity split,
  // tau_inf 1 -> 6 px took the TP rate at eps_h = 1 px from 49 to 70 %, recall
  // 41 -> 47 %) leaves only points whose motion separates planes. Pass 1 for
  // the paper's threshold.
  double tau_inf_px = 6.0;
};

// The pair's motion and its thresholding.
struct InfinityResult : PairMotionReport {
  std::vector<double> parallax_px;   // per correspondence, w.r.t. R_later_from_earlier
  std::vector<int> kept_indices;     // parallax_px >= tau_inf_px (ascending)
  std::vector<int> dropped_indices;  // parallax_px < tau_inf_px: plane at infinity (ascending)
};

// Estimates the pair's motion (EstimatePairMotion with min_parallax_px =
// tau_inf_px) and thresholds by its rotation.
// InvalidArgument: tau_inf_px <= 0, or EstimatePairMotion's (intrinsics,
// options, non-finite coordinates). Internal: OpenCV threw (not expected for
// finite input).
// prior: a guess of the motion for the seeded fast path (null: full path only).
StatusOr<InfinityResult> ThresholdInfinity(const std::vector<Correspondence>& correspondences,
                                           const Intrinsics& intrinsics,
                                           const InfinityOptions& options,
                                           const PairMotionPrior* prior = nullptr);

// The thresholding alone, given the pair's motion (motion.R_later_from_earlier).
InfinityResult ThresholdInfinity(const std::vector<Correspondence>& correspondences,
                                 const Intrinsics& intrinsics, double tau_inf_px,
                                 PairMotionReport motion);

}  // namespace slapse
