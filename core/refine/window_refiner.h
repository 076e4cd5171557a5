// Sliding-window refinement of anchor poses and planes (docs/METHOD.md
// "Windowed refinement").
//
// The window holds the last `window_anchors` anchors (poses world_from_cam)
// and every plane observed by one of the window's anchor pairs. One plane is
// one set of parameters across all pairs that observe it: a plane seen by
// several pairs is fitted over their combined (longer) baseline.
//
// Frames and conventions (those of core/ekf/plane_ekf.h):
//  - Anchor i has pose world_from_cam_i = (R_i, c_i).
//  - Pair (i-1, i): prev_from_cur = (R, t) with R = R_{i-1}^T R_i,
//    t = R_{i-1}^T (c_i - c_{i-1}); X_{i-1} = R X_i + t.
//  - A plane is held as pi_r (pi^T X = 1) in the camera r of the window's
//    oldest anchor, which is held constant during a solve. In camera i
//    (r_from_i = (R_ri, t_ri)):  pi_i = R_ri^T pi_r / (1 - pi_r^T t_ri)
//    (the EKF's plane transition).
//  - Residual of a macroblock x_i (later anchor) with merged partner x_{i-1}:
//      r = (dehom(K (R + t pi_i^T) K^-1 x_i) - x_{i-1}) / s,
//    s^2 = Lemma 2's variance + extra_sigma_px^2 (the EKF's measurement
//    noise), with Huber weights at huber_k (normalised units) taken at the
//    start of each solve (one IRLS step per solve; every anchor solves again).
//
// Gauge. The oldest pose is constant (6 dof). Monocular scale is the 7th
// gauge freedom; it is carried, not re-chosen, by
//  (a) a prior on the oldest step's length (the step from the oldest anchor
//      to the next), at its value from the previous solve, with
//      gauge_step_rel_sigma: the scale the window inherits; once the camera
//      height is metric (SetRoadHeight), with the looser
//      metric_gauge_step_rel_sigma: the road's height (c) then measures the
//      scale, and the inherited one only steadies it;
//  (b) the planes seen across the window: each is one unknown for all pairs
//      that see it, so a new plane's scale is tied to the steps that saw the
//      old ones;
//  (c) the road: its distance from the oldest camera (the camera height) has
//      a prior with road_height_rel_sigma at the metric camera height, or
//      with (e) on at the reference height (below), held from then on (a
//      car's camera stays at one height above the road; a prior at each
//      solve's previous estimate, used until then and with (e) off, lets
//      the height and with it the scale random-walk);
//  (d) the motion prior: consecutive steps' velocities (t / dt, in the body
//      frame) and angular velocities differ by a random walk (sigma ~
//      sqrt(dt)), so a step that sees only new planes cannot take a new
//      scale in one step;
//  (e) the road's attitude: a car-mounted camera sees the road under one
//      attitude (its mount's pitch and roll; the car pitches and rolls on its
//      suspension by about a degree), so each pose's road normal has a prior
//      at a reference normal, with road_attitude_sigma_deg per axis (0:
//      off). The references of (c) and (e) are the mean road over the first
//      road_reference_solves solves of a full window in which at least half
//      the pairs saw the road (solved without (e)), then held.
//      Without it, short baselines (one-frame H.264 IPPP pairs) let the
//      cameras' pitch relative to the road drift by degrees over seconds, and
//      a tilted road changes every road block's depth, hence the step lengths
//      (docs/METHOD.md "The road's attitude");
//  (f) the road's level: the car keeps its height above the road, so each
//      camera of the window lies in the plane through the oldest camera
//      parallel to the road, to road_level_rel_sigma of the road's distance
//      per step (a random walk: sqrt(k) of it k steps on), as the filter's
//      road_height_rel_sigma pseudo-measurement holds each step. It ties the
//      road's attitude to the direction of travel, which the whole image
//      measures (docs/METHOD.md "The road's level in the window").
// The references of (c) and (e) belong to the trajectory, not the window:
// Reset keeps them, Rescale scales the height.
// Cost: Levenberg-Marquardt (core/refine/block_lm.h: Ceres' steps, the
// normal equations accumulated per residual block into one dense matrix of
// the window's 30-60 tangent parameters), at most max_iterations; macroblocks
// per (pair, plane) are subsampled to max_mbs_per_plane, so a solve's cost is
// bounded by the window size.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/camera.h"
#include "core/common/plane.h"
#include "core/common/rigid3.h"
#include "core/common/status.h"

namespace slapse {

struct WindowRefinerOptions {
  int window_anchors = 6;               // poses in the window (>= 3)
  int max_iterations = 6;               // Levenberg-Marquardt iterations per solve
  int max_mbs_per_plane = 48;           // per pair and plane, evenly subsampled
  double extra_sigma_px = 1.0;          // added in quadrature to Lemma 2's variance
  double huber_k = 2.0;                 // Huber threshold, normalised residual units
  double gauge_step_rel_sigma = 0.002;  // (a): oldest step's length, relative
  // (a) once the camera height is metric. A window restarted after a step
  // without planes starts from the filter's step; at 0.002 its one step held
  // that length against the metric height (c), and the camera-height metric
  // trajectories of the MPEG-2 tuning drives came out 1.8 % short at the
  // median, 9 of 37 beyond 3 % (docs/TRAJECTORY.md "Session 33").
  double metric_gauge_step_rel_sigma = 0.03;
  double road_height_rel_sigma = 0.01;  // (c): road distance, relative
  // (e): road normal per camera, deg per axis; 0 = off (then (c) is at each
  // solve's previous estimate and nothing is held).
  double road_attitude_sigma_deg = 1.0;
  // (f): each camera's height change above the road, relative to the road's
  // distance, per step from the oldest camera; 0 = off. 0.01 as the
  // filter's EkfOptions::road_height_rel_sigma (1.5 cm per step at 1.5 m:
  // bumps, suspension). The simulator's cameras never leave their height,
  // so a tighter value measured better there (0.003) and is not taken.
  double road_level_rel_sigma = 0.01;
  // (c) and (e)'s references: the mean road over this many solves of a full
  // window in which at least half the pairs saw the road (>= 1). One solve
  // of a short-baseline window is off by a degree or two; 8 (0.27 s of
  // one-frame pairs at 30 fps) averaged it out on the tuning drives, before
  // the drift the prior is for (docs/METHOD.md "The road's attitude").
  int road_reference_solves = 8;
  // (d): the velocities' random walk, as in the EKF's process model: over
  // dt seconds the body-frame velocity changes by speed_change_rel_per_sqrt_s
  // * sqrt(dt) relative to the speed (0.15: 5.5 % over one 30 fps IBBBP
  // anchor step of 0.133 s, 15 % over a second) and the angular velocity by
  // angular_rate_change_rad_s_per_sqrt_s * sqrt(dt) rad/s. The spread over a
  // given time does not depend on the anchor rate (docs/METHOD.md "The
  // refiner's motion prior and the anchor rate").
  double speed_change_rel_per_sqrt_s = 0.15;
  double angular_rate_change_rad_s_per_sqrt_s = 0.5;
  // A plane id whose guess (the filter's plane) differs from the window's
  // plane by more than this angle or distance ratio is a different surface
  // under the same id (see Push).
  double reassociate_max_angle_deg = 10.0;
  double reassociate_max_distance_ratio = 1.3;
  // A solve whose final_rms (normalised residuals, ~0.3-0.6 when the window
  // fits) stays above this does not fit its vectors: its guess was beyond
  // repair. Its result is not used (WindowRefineReport::rejected). The
  // tuning drives' 3352 solves: at most 0.62; a 60 fps 2 Mbit/s H.264 drive
  // whose refined step then grew 2x and 56x per solve: 6.8 and 28.
  double max_final_rms = 3.0;

  // InvalidArgument (prefixed with `who`) unless window_anchors >= 3,
  // max_iterations >= 1, max_mbs_per_plane >= 4, road_reference_solves >= 1,
  // every sigma (but road_attitude_sigma_deg and road_level_rel_sigma,
  // >= 0), the angle and
  // max_final_rms are > 0 and the distance ratio > 1.
  Status Check(const std::string& who = "WindowRefinerOptions") const;
};

// One plane's macroblocks in one anchor pair (later anchor -> earlier).
struct WindowPlaneObservation {
  int plane_id = -1;  // the same id in every pair that sees this plane
  std::vector<Eigen::Vector2d> x_later_px, x_earlier_px;
  std::vector<double> variance_px2;  // Lemma 2, per axis
};

struct WindowRefineReport {
  bool solved = false;  // the window holds the solve's poses and planes
  // Solved, but final_rms > max_final_rms: nothing of the solve was kept
  // (solved false); the caller restarts the window (Reset).
  bool rejected = false;
  int anchors = 0, planes = 0, residuals = 0;
  double initial_rms = 0.0, final_rms = 0.0;  // weighted normalised residuals
  // Newest step's length after / before the solve.
  double newest_step_ratio = 1.0;
  bool road_in_window = false;
  double road_distance = 0.0;  // from the newest camera, trajectory units (0: no road)
  int road_pairs = 0;          // pairs in the window that observed the road
};

class WindowRefiner {
 public:
  explicit WindowRefiner(const Intrinsics& intrinsics, WindowRefinerOptions options = {});

  // Adds anchor `index` at time `timestamp_s` with a predicted pose (e.g. the
  // previous refined pose composed with the EKF's step), the observations of
  // the pair that ends at it (empty for the first anchor) and an initial
  // value, pi in this anchor's camera, for each plane id the window does not
  // hold yet (`plane_guess_cam`; planes without one are skipped). `road_id`:
  // the plane id of the road (-1: none). A plane id whose guess differs from
  // the window's plane beyond reassociate_max_angle_deg / _distance_ratio is
  // taken as a new surface: the old plane stays in the window under an
  // internal id. Drops the oldest anchor
  // beyond the window (and planes no pair in the window sees).
  void Push(int64_t index, double timestamp_s, const Rigid3d& world_from_cam,
            std::vector<WindowPlaneObservation> observations,
            const std::map<int, Eigen::Vector3d>& plane_guess_cam, int road_id);

  // Solves the window. On success the poses() and planes are updated.
  // A window with fewer than 2 anchors is left as is (solved = false).
  Status Refine(WindowRefineReport* report);

  // Metric road height: from now on the road prior (c) uses this distance
  // (trajectory units) instead of its estimate (the running one, or the
  // reference with (e) on), and the gauge (a) metric_gauge_step_rel_sigma;
  // Reset keeps both.
  void SetRoadHeight(double height) {
    road_height_ = height;
    metric_height_ = true;
  }

  // Multiplies every length by s (poses, planes, priors).
  void Rescale(double s);
  // Empties the window (the filter restarted, or a step without planes); the
  // road references of (c) and (e) stay: they belong to the trajectory, which
  // continues.
  void Reset();
  // The references (c) and (e) hold; nullopt until they are taken (the
  // height: or set by SetRoadHeight).
  std::optional<double> road_height() const { return road_height_; }
  std::optional<Eigen::Vector3d> road_normal_cam() const { return road_normal_cam_; }

  size_t size() const { return anchors_.size(); }
  int64_t index(size_t k) const { return anchors_[k].index; }
  const Rigid3d& world_from_cam(size_t k) const { return anchors_[k].world_from_cam; }
  // The road's inverse depth pi in the newest camera (nullopt: no road in the window).
  std::optional<Eigen::Vector3d> RoadInNewest() const;

 private:
  struct Anchor {
    int64_t index = -1;
    double timestamp_s = 0.0;
    Rigid3d world_from_cam;
    std::vector<WindowPlaneObservation> observations;  // pair ending here
  };
  void DropOldest();
  void Reassociate(int plane_id, const Eigen::Vector3d& guess_cam, const Rigid3d& world_from_cam);
  // Refine's parts: the problem over the window (defined in the .cc),
  // with the poses from index `first` on being the window's anchors.
  struct Problem;
  void AddTransferResiduals(Problem* wp, size_t first, WindowRefineReport* rep) const;
  void AddGaugeAndPriors(Problem* wp, size_t first, WindowRefineReport* rep);
  void AccumulateRoadReferences(const Problem& wp, const WindowRefineReport& rep);

  Intrinsics intrinsics_;
  WindowRefinerOptions options_;
  std::deque<Anchor> anchors_;
  std::map<int, Plane3d> planes_world_;  // plane id -> the plane in the world
  std::map<int, int> plane_solves_;      // plane id -> solves it took part in
  int road_id_ = -1;
  int next_internal_id_ = -2;  // ids for planes moved aside by Reassociate (-1: none)
  // The trajectory's road references (kept by Reset): (c) the camera height
  // (trajectory units) and (e) the road's unit normal in the camera.
  std::optional<double> road_height_;
  bool metric_height_ = false;  // road_height_ set by SetRoadHeight
  std::optional<Eigen::Vector3d> road_normal_cam_;
  // Sums over the solves averaged into them so far (until they are held).
  Eigen::Vector3d road_normal_sum_ = Eigen::Vector3d::Zero();
  double road_height_sum_ = 0.0;  // trajectory units, scaled by Rescale
  int road_reference_solves_ = 0;
  // The anchor before the window (constant): the oldest step's velocity prior.
  std::optional<Anchor> before_;
};

}  // namespace slapse
