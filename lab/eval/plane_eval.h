// True positives of plane extraction against the simulator's ground truth
// (issue 3; the definition is stated in docs/PLANE_EXTRACTION.md).
//
// An extracted plane of anchor pair (k, k+1) -- a macroblock set of the later
// anchor plus its homography x_earlier ~ H x_later -- is a true positive when
//  1. purity: at least `min_purity` of its macroblocks with a definite label
//     (a plane id, sky or clutter; blocks straddling an edge, "mixed", are not
//     counted) lie on a true plane whose true motion the extracted homography
//     reproduces: |H x - H_true(label) x| <= max_transfer_px at the block. So
//     sky, trees and any surface the homography does not describe count
//     against it, while adjacent facades too close to coplanar for a 1 px
//     homography to tell apart count as one surface (as a person labelling
//     "the wall" would); and at most `max_mixed_share` of all its blocks are
//     mixed. A block labelled mixed whose samples lie, to the labelling
//     coverage (kMbLabelCoverage), on true planes that all move as H says at
//     the block -- the seam of two flush facades -- is such a wall block (a
//     definite one, counted for the largest of those planes); without the
//     shares (drives simulated before mb_mixed.txt) every mixed block counts
//     as mixed; and
//  2. geometry: its homography agrees with the true plane-induced homography
//     H_true = K (R + t n^T / d) K^-1 of its majority true plane P (true
//     poses of the two anchors, P in the later camera): the mean transfer
//     distance |H x - H_true x| over its blocks is at most `max_transfer_px`.
#pragma once

#include <set>
#include <vector>

#include <Eigen/Core>

#include "core/merge/correspondence.h"
#include "core/planes/plane_extraction.h"
#include "lab/gt/ground_truth.h"

namespace slapse {

struct PlaneTruthOptions {
  double min_purity = 0.9;
  double max_mixed_share = 0.3;
  double max_transfer_px = 1.0;
  int min_visible_mbs = 20;  // a true plane counts as visible with this many labelled MBs
};

struct PlaneMatch {
  int track_id = -1;
  int gt_plane = -1;         // the majority true plane, -1 if none
  double purity = 0.0;       // share of definitely labelled MBs whose true motion H reproduces
  double mixed_share = 0.0;  // share of MBs straddling an edge
  double transfer_px = 0.0;  // mean |H x - H_true x| over its MBs (inf without gt_plane)
  bool true_positive = false;
};

struct PairPlaneEvaluation {
  std::vector<PlaneMatch> matches;  // one per extracted plane
  std::set<int> visible;            // true planes with >= min_visible_mbs MBs in the later anchor
  std::set<int> visible_near;       // ... of kind road or facade (background has no parallax)
  std::set<int> found;              // true planes matched by a true positive
};

// True plane-induced homography of plane `id` between two frames:
// x_earlier ~ H x_later.
Eigen::Matrix3d TrueHomography(const GroundTruth& gt, int plane_id, int64_t earlier, int64_t later);

PairPlaneEvaluation EvaluatePlanes(const AnchorPair& pair,
                                   const std::vector<ExtractedPlane>& planes, const GroundTruth& gt,
                                   const PlaneTruthOptions& options = {});

}  // namespace slapse
