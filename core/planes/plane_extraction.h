// Multi-plane homography RANSAC with plane tracking (paper Sec. V-C;
// docs/METHOD.md "Plane extraction"), in streaming form: one call per anchor
// pair, in display order.
//
// Homography convention: x_earlier ~ H_earlier_from_later * x_later (pixels,
// homogeneous), as in the paper's x_k ~ H x^c_{k+1}. A correspondence is an
// inlier of H iff ||x_earlier - dehom(H x_later)|| <= eps_h_px (transfer error
// in the earlier anchor). H is estimated by EpipolarPlaneEstimator when the
// pair's motion is known (use_motion; 3-parameter planes consistent with it),
// else by HomographyEstimator (normalised DLT); either way ||H||_F = 1 and
// (H x_later)_z > 0 on its inliers.
// For a plane n^T X = d in the *later* camera frame (n unit, d > 0) and
// earlier_from_later = (R, t) (X_earlier = R X_later + t):
//   X_earlier = (R + t n^T / d) X_later  =>  H ~ K (R + t n^T / d) K^{-1}.
//
// Per Process call:
//  1. Tracking (only when pair.earlier_index equals the previous pair's
//     later_index): each remembered plane owns a set of MB cells of that anchor,
//     which is this pair's earlier anchor. Its sampling subset is the remaining
//     correspondences whose x_earlier_px falls into one of those cells (the
//     MB grid of core/common/mb_grid.h). RANSAC samples only from the
//     subset and scores on all remaining correspondences. The track continues
//     (same track_id, tracked = true) iff the plane has >= min_mbs_per_plane MBs
//     AND at least min_track_overlap of the subset are its inliers. Scoring on
//     all points lets the plane grow, but also lets a few foreign points in the
//     subset (a neighbour's border, or a new plane that took over the old MBs)
//     propose a bigger plane that wins on total support; the overlap guard
//     turns that hijack into a lost track.
//     Planes are tried in ascending track_id; each removes its inliers.
//  2. Discovery: sequential RANSAC on what remains; each plane with
//     >= min_mbs_per_plane MBs gets a new track_id (never reused, also not after
//     Reset) and removes its inliers. Stops at max_planes planes (tracked
//     included), when fewer than 4 correspondences remain, or when the best
//     model has fewer than min_mbs_per_plane MBs. A pair that tracked a plane
//     discovers at most every min_discovery_interval_s (beyond the paper).
//  3. The planes' MB sets (mb_index, later anchor) are remembered for the next pair.
// Beyond the paper (options below; all off gives the paper's method):
// consensus sets (steps 1 and 2) are post-processed. Blocks with fewer than
// min_mb_neighbours of their 8 neighbour cells in the set are dropped, the rest
// is split into spatially connected MB components and only the largest is kept
// (the others return to the pool); that component is refitted by least
// squares (normalised DLT), re-scored on all remaining correspondences with
// eps_h and peeled / split again, up to refit_iterations times while the kept
// set does not shrink. The min_mbs_per_plane and min_track_overlap tests apply
// to the final set. In discovery, a best model whose kept set is too small no
// longer ends the search at once: its RANSAC inliers are set aside (reported
// as unassigned) and the search goes on, up to max_failed_discoveries times
// in a row.
// Deterministic: RANSAC call j of a Process call is seeded from (seed, j).
#pragma once

#include <cstdint>
#include <optional>
#include <set>
#include <vector>

#include <Eigen/Core>

#include "core/common/camera.h"
#include "core/common/rigid3.h"
#include "core/common/status.h"
#include "core/merge/correspondence.h"
#include "core/planes/infinity.h"

namespace slapse {

struct PlaneExtractionOptions {
  double eps_h_px = 1.0;       // homography inlier threshold (transfer error)
  int min_mbs_per_plane = 20;  // distinct MBs a plane needs
  int max_planes = 8;          // per anchor pair, tracked + new
  // RANSAC trials per plane search, at most. The adaptive count reaches it
  // only for planes with few blocks among many (about 1 in 10 searches on a
  // 640x480 MPEG-2 drive, most of them the last, failing one of a pair);
  // 2000 -> 1000 took 19 % of the trials off avenue-1 and changed neither
  // Table I (eval-planes, eps_h 1 px: TP 90.5 %, recall 48.5 %) nor the
  // tuning drives' ATE (one drive 0.12 -> 0.13 %); 500 did (MPEG-2 eps_D
  // median 1.84 -> 2.15 %).
  int max_trials_per_plane = 1000;
  int min_trials_per_plane = 10;
  double confidence = 0.999;
  double min_track_overlap = 0.5;  // fraction of a track's sampling subset that must be inliers
  uint64_t seed = 0;
  // Spatial connectivity of consensus sets (beyond the paper; see the file
  // comment). A consensus set is split into connected components of its MB
  // cells on the later anchor's grid, two cells being neighbours when their
  // column and row differ by at most connectivity_radius_mbs (1: 8-connected);
  // only the largest component is kept, the rest goes back to the pool. A
  // homography fits points anywhere in the image (distant facades and the
  // background near the focus of expansion, with little parallax, fit many of
  // them), so without this one plane collects blocks of several surfaces.
  // 0 turns the split (and the setting aside of failed models) off.
  int connectivity_radius_mbs = 1;
  // Connections may also cross up to this many consecutive MB cells without
  // any correspondence (intra-coded / MV-less blocks, common on the fast near
  // road and on low-contrast verges and fields), so a sparsely measured
  // surface stays one component; cells whose correspondences belong
  // elsewhere (other planes, plane at infinity) never connect. 1 since
  // session 21, with min_mb_neighbours = 0 (below): on a rural drive
  // (rural-15, H.264 IPPP) the ground plane covers ~550 MBs but only ~150 of
  // them have a correspondence, scattered, so no component reached
  // min_mbs_per_plane and 97 of 124 anchors were posed without a plane
  // (ATE 3.06 %; 0.63 % with both). Tuning drives (seeds 1-15 odd, 48 per
  // profile; `slapse eval-trajectory`, ATE median / worst / mean %):
  // h264-ippp 0.16 / 3.06 / 0.333 -> 0.12 / 1.14 / 0.249 (gap 1 alone 0.14 /
  // 1.84 / 0.308, peeling off alone 0.15 / 3.40 / 0.335); mpeg2-ibbbp 0.19 /
  // 2.45 / 0.463 -> 0.15 / 2.98 / 0.460. Table I (eval-planes, seeds 1-5,
  // eps_h = 1 px) TP 90.6 -> 81.7 %, recall 48.6 -> 52.2 %: more planes
  // mix surfaces at extraction, while the filter's map holds (mean plane
  // eps_d and eps_n over the tuning drives equal or lower; the H.264
  // medians a little higher, docs/TRAJECTORY.md "Session 21"). 0: off.
  int max_empty_gap_mbs = 1;
  // Before the split, blocks with fewer than this many of their 8 neighbour
  // cells in the consensus set are dropped (isolated blocks, thin spurs along
  // edges); 0 keeps them. 2 gained TP +3 points at a recall cost of ~2
  // points (eps_h = 1 px) on the simulated urban drives, but on a sparsely
  // measured ground it peels the scattered road blocks away; 0 since
  // session 21, with max_empty_gap_mbs = 1 (the figures above).
  int min_mb_neighbours = 0;
  // Least-squares refits of a kept component (then re-scoring with eps_h and
  // re-splitting) after RANSAC; 0 turns them off. On the simulated drives one
  // refit is best (eps_h = 1 / 2 px, TP / recall %: none 72.9 / 44.2 and
  // 54.7 / 39.8; one 72.6 / 46.8 and 58.3 / 43.2; three 69.9 / 47.3 and
  // 57.7 / 43.3).
  int refit_iterations = 1;
  // Discovery sets aside at most this many consecutive best models whose
  // largest component is below min_mbs_per_plane (or that the orientation
  // prior rejects; their inliers are set aside for the rest of the pair and
  // reported as unassigned) and stops at the next one. 0: stop at the first.
  // A failing search is discovery's most expensive: its trial count runs to
  // max_trials_per_plane. 2 -> 1 in session 35: on the 2 Mbit/s H.264
  // camera stream discovery 0.87 -> 0.69 G instructions (docs/BENCHMARKS.md
  // "Session 35"); tuning drives (`slapse eval-trajectory --drives tuning`,
  // ATE median / mean / worst %) mpeg2-ibbbp 0.13 / 0.264 / 1.35 -> 0.13 /
  // 0.261 / 1.24, h264-ippp 0.10 / 0.175 / 1.62 -> 0.10 / 0.176 / 1.62;
  // Table I at eps_h 1 px TP 82.6 -> 82.3 %, recall 52.8 -> 52.4 %. 0 saved
  // 0.43 G but cost MPEG-2 accuracy (mean ATE 0.264 -> 0.282 %).
  int max_failed_discoveries = 1;
  // With the pair's motion (Process's `motion`), fit planes as 3-parameter
  // homographies H = K (R + t m^T) K^-1 consistent with it
  // (core/estimators/epipolar_plane.h: 3-point samples, planes in front of
  // the camera) instead of free 8-parameter ones. Beyond the paper.
  bool use_motion = true;
  // Motion-constrained tracking: a remembered plane continues only if the
  // plane found on its MBs is the remembered one moved by the pair's motion,
  // track_change <= this (relative change of m; see ExtractedPlane). Else the
  // MBs were taken over by another surface (a tree in front of a facade, the
  // next building): the track is lost and its points return to discovery, so
  // the filter never sees one plane jump to another's depth. 0.15 (true
  // tracked planes: median 0.056): at 0.25 a track slid onto the next
  // building 20 % further away on two of five drives and bent the scale
  // (bench/table2.sh over seeds 1-10, mean eps_D 0.10 / 0.125 / 0.15 / 0.20 /
  // 0.25: 4.1 (seeds 1-5) / 2.8 / 2.5 / 3.2 / 3.7 %); Table I unchanged.
  double max_track_change = 0.15;
  // Street-scene prior (beyond the paper): streets are built of vertical
  // walls and the horizontal road. A motion-constrained plane (m_later) is
  // kept only if its unit normal n is within max_facade_tilt_deg of
  // horizontal (|n . down| <= sin: a wall) or within max_road_tilt_deg of
  // down (n . down >= cos: the road below the camera, the one road test of
  // core/common/road.h; a ceiling is no road). `down` is the vertical in
  // the camera frame: the camera's y axis at first (a camera mounted about
  // level), then learnt from the road planes found (the mean of their
  // normals, moved with each pair's rotation), so a pitched camera is
  // handled once the road was seen. Other orientations were nearly all
  // slabs of tree canopies or mixes of two surfaces (simulated drives: 99 of
  // 108 such planes were false positives). A rejected new plane's inliers
  // are set aside like a plane too small; a rejected track is lost. A
  // negative angle turns the prior off (scenes that are not streets).
  // 5 deg: the learnt vertical is within 0.3 deg of the truth (median; 90 %
  // within 1.2 deg) and 90 % of true facade planes within 3.1 deg of
  // vertical, false positives spread wider (median 2.7 deg). Simulated
  // drives, eps_h = 1 px, TP / recall: 8 deg 89.5 / 50.2 %, 6 deg 90.5 /
  // 48.9 %, 5 deg 90.9 / 48.8 %, 4 deg 91.4 / 48.1 %; Table II mean eps_D
  // 2.84 % at 8 deg, 2.65 % at 5 deg.
  double max_facade_tilt_deg = 5.0;
  double max_road_tilt_deg = 15.0;
  // Until road planes have taught the vertical, the camera's y axis stands
  // in for it, and a camera pitched or rolled by a few degrees tilts every
  // wall by as much: the facade tolerance is widened by this margin, which
  // shrinks as road blocks teach the vertical (to a half after 100 of them,
  // the blocks that move the vertical half way; see LearnVertical). A
  // single small road patch moves the vertical a fifth of the way and must
  // not drop the whole margin: on a 3.9 deg pitched camera at an
  // intersection (reporting intersection-6, MPEG-2) the walls then looked
  // 6-7 deg tilted, every plane of a pair was refused and the filter lost
  // its scale (docs/TRAJECTORY.md, session 27).
  double unlearnt_vertical_margin_deg = 3.0;
  // Boundary trim (beyond the paper): after the refits, blocks on the border
  // of the kept set (an 8-neighbour cell inside the grid not in the set) whose
  // transfer error exceeds boundary_residual_frac * eps_h_px are dropped, and
  // the largest component of the rest is kept. Border blocks mostly straddle
  // an edge, and their MVs mix the two sides. < 0 turns the trim off.
  double boundary_residual_frac = -1.0;
  // Process(pair, infinity, ...) with a motion: fit only the E-inliers
  // (InfinityResult::e_inlier_mask); the others are reported as unassigned
  // by omission. Beyond the paper.
  bool drop_e_outliers = false;
  // Boundary trim: cells without any MV do not make a block a border block
  // (only cells whose MVs belong elsewhere do).
  bool boundary_ignore_empty = false;
  // Discovery samples locally (Ransac<>::Estimate's neighbours, NAPSAC-like):
  // a uniformly drawn point and two more from the points whose later-anchor
  // MB cells are within this many cells (column and row) of its cell. A plane's
  // points are spatially clustered, so such samples are all-inlier far more
  // often than uniform ones and the adaptive trial count drops by an order of
  // magnitude. 0: uniform sampling (the paper's).
  int local_sampling_radius_mbs = 3;
  // RANSAC pre-test (RansacOptions::pretest_points, Capel's bail-out): a
  // hypothesis is scored on all points only if, on a fixed random set of this
  // many points, it has at least half the best model's inliers. 0: off.
  int ransac_pretest_points = 100;
  // Discovery (step 2) runs at most this often, stream seconds: a pair that
  // ends less than this after the last discovering pair's later anchor and
  // tracked at least one plane only tracks (its other points are
  // unassigned); without a tracked plane a pair always discovers. A new
  // surface stays in view for many pairs, and on one-frame IPPP pairs
  // (30-60 per second) discovery was a quarter of the pipeline's time. 0.1 s
  // changes nothing where anchors are >= 0.1 s apart (IBBBP up to 30 fps,
  // IPPP at 10 fps). Tuning drives (`slapse eval-trajectory --drives tuning`,
  // ATE median / worst, eps_D median), 0 -> 0.1 -> 0.2 s: h264-ippp 0.31 /
  // 2.76 / 2.03 -> 0.30 / 2.76 / 1.59 -> 0.29 / 2.76 / 1.87 %; mpeg2-ibbbp
  // 0.28 / 2.02 / 1.84 -> 0.32 / 1.85 / 1.81 -> 0.32 / 1.54 / 1.84 %. Plane
  // fitting per pair on a 2 Mbit/s H.264 IPPP stream 0.88 -> 0.57 -> 0.52 ms
  // (docs/BENCHMARKS.md). 0.1: most of the saving, the smaller change.
  double min_discovery_interval_s = 0.1;
};

// The relative motion of an anchor pair, when the epipolar geometry was
// observed (ThresholdInfinity's has_motion): X_later = R X_earlier + t with
// t != 0 (up to scale).
struct PairMotion {
  Intrinsics intrinsics;
  Rigid3d later_from_earlier;
};

struct ExtractedPlane {
  int track_id = -1;
  Eigen::Matrix3d H_earlier_from_later = Eigen::Matrix3d::Identity();  // x_earlier ~ H x_later
  std::vector<int> correspondence_indices;  // into pair.correspondences, ascending
  std::vector<int> mb_indices;              // distinct MB indices in the later anchor, ascending
  bool tracked = false;                     // continued from the previous pair
  // Root mean square of the transfer errors |x_earlier - H x_later| of its
  // correspondences, px: near the MV noise for a real plane, near eps_h / sqrt(2)
  // for points that fit only by accident.
  double rms_transfer_px = 0.0;
  // Motion-constrained fits: the plane m = n / d in the later camera frame
  // (m . X = 1), in the unit of the pair's translation (|t| = 1).
  std::optional<Eigen::Vector3d> m_later;
  // Tracked planes with m on both pairs: |m_later - m_predicted| / |m_predicted|,
  // m_predicted being the previous pair's plane moved by this pair's motion;
  // -1 when not available.
  double track_change = -1.0;
  // Tracked planes only: the sampling subset (correspondences on the track's
  // old MBs) and how many of it are inliers of this plane.
  int track_subset_size = 0;
  int track_subset_inliers = 0;
};

struct PlaneExtractionResult {
  std::vector<ExtractedPlane> planes;   // tracked planes first (ascending track_id), then new ones
  std::vector<int> unassigned_indices;  // kept correspondences on no plane, ascending
  int num_tracks_lost = 0;              // remembered planes that were not found again
};

class PlaneExtractor {
 public:
  explicit PlaneExtractor(PlaneExtractionOptions options);

  // kept_indices: the correspondences left after ThresholdInfinity (duplicates
  // ignored). InvalidArgument (state unchanged) when an index is out of range,
  // the MB grid is empty, or a kept correspondence has an mb_index outside it
  // or non-finite coordinates.
  // motion: the pair's relative motion if known (see use_motion), else null.
  StatusOr<PlaneExtractionResult> Process(const AnchorPair& pair,
                                          const std::vector<int>& kept_indices,
                                          const PairMotion* motion = nullptr);
  // The same after ThresholdInfinity: its kept correspondences, and its motion
  // when it observed one (has_motion).
  StatusOr<PlaneExtractionResult> Process(const AnchorPair& pair, const InfinityResult& infinity,
                                          const Intrinsics& intrinsics);

  // Forgets the remembered planes (track ids keep increasing).
  void Reset();

  // Takes the last Process call back: the planes, vertical and discovery
  // time remembered before it are restored, so that a pair extended over a
  // longer baseline (FrontEnd::ExtendBaseline: same earlier anchor, a later
  // one further on) tracks from the anchor before it. Track ids the call
  // gave stay used. False (nothing changed) when no call is left to take
  // back: none since the last Reset or Rewind.
  bool Rewind();

  // The street-scene prior's vertical (unit, pointing down) in the camera
  // frame of the last later anchor processed.
  const Eigen::Vector3d& vertical_down() const { return down_; }

 private:
  class PairFit;  // one Process call's working set (plane_extraction.cc)
  struct Track {
    int track_id;
    std::set<int> mb_cells;  // MB indices in the anchor with display index last_later_index_
    std::optional<Eigen::Vector3d> m_later;  // the plane in that anchor's frame, if known
  };

  // Process's steps.
  static StatusOr<std::vector<int>> ValidatedKept(const AnchorPair& pair,
                                                  const std::vector<int>& kept_indices);
  void TrackPlanes(const AnchorPair& pair, const PairMotion* motion, PairFit* fit,
                   PlaneExtractionResult* result);
  void DiscoverPlanes(PairFit* fit, PlaneExtractionResult* result, std::vector<int>* set_aside);
  // Whether `pair`, after tracking `tracked`, runs discovery
  // (min_discovery_interval_s).
  bool DiscoveryDue(const AnchorPair& pair, const PlaneExtractionResult& tracked) const;
  void LearnVertical(const PlaneExtractionResult& result);
  static double TrackChange(const Eigen::Vector3d& m_remembered, const Eigen::Vector3d& m_later,
                            const PairMotion& motion);
  int MinMbs(const PairFit& fit) const;                   // MBs a plane needs
  bool IsRoad(const ExtractedPlane& plane) const;         // m_later set and non-zero
  bool OrientationOk(const ExtractedPlane& plane) const;  // the street-scene prior

  // Road blocks that move the vertical half way to their normals, and that
  // halve the unlearnt-vertical margin (LearnVertical, OrientationOk).
  static constexpr double kVerticalHalfBlocks = 100.0;

  // What Process remembers between pairs, before the last call (Rewind).
  struct Memory {
    std::vector<Track> tracks;
    Eigen::Vector3d down;
    double vertical_road_blocks;
    int64_t last_later_index;
    bool has_previous;
    double last_discovery_s;
  };

  PlaneExtractionOptions options_;
  std::optional<Memory> before_;
  std::vector<Track> tracks_;
  // The vertical (unit, pointing down) in the camera frame of the last later
  // anchor: the street-scene prior's reference.
  Eigen::Vector3d down_ = Eigen::Vector3d::UnitY();
  double vertical_road_blocks_ = 0.0;  // road blocks that have refined down_ (LearnVertical)
  int64_t last_later_index_ = -1;
  bool has_previous_ = false;
  double last_discovery_s_ = -1.0;  // later anchor's timestamp of the last discovery (-1: none)
  int next_track_id_ = 0;
};

// `mask` (one entry per point, point j in MB cell mb_of[j]) without the points
// whose squared residual exceeds max_sq_residual and whose cell lies on the
// border of the mask's cells: some 8-neighbour cell inside the grid is not in
// the mask. The grid's own border is no edge of the set.
std::vector<char> TrimBoundaryCells(const std::vector<int>& mb_of, const std::vector<char>& mask,
                                    const std::vector<double>& sq_residuals, int mb_cols,
                                    int mb_rows, double max_sq_residual,
                                    const std::vector<char>& empty = {});

}  // namespace slapse
