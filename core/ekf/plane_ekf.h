// EKF over camera motion and planes (paper Sec. VI; docs/METHOD.md "EKF").
//
// Frames and conventions (one set, used everywhere in this file):
//  - C_k is the camera frame at anchor k (x right, y down, z forward).
//  - The step motion of anchor k is prev_from_cur = (R_k, t_k):
//      X_{k-1} = R_k X_k + t_k,
//    i.e. R_k rotates C_k coordinates into C_{k-1} and t_k is the position of
//    C_k's centre in C_{k-1}.
//  - A plane is kept in inhomogeneous form pi = n / d in C_k, so that
//    pi^T X = 1 for points X of the plane (n unit normal, d > 0 its distance).
//  - Plane transition C_k -> C_{k+1}:  pi_{k+1} = R^T pi_k / (1 - pi_k^T t),
//    with (R, t) = (R_{k+1}, t_{k+1}).
//  - Observation: a macroblock centre x_k of the plane in anchor k maps to
//      x_{k-1} ~ K (R_k + t_k pi^T) K^-1 x_k
//    (X_{k-1} = R X_k + t (pi^T X_k) on the plane), which is the
//    correspondence x_earlier ~ H x_later of core/merge.
//  - Motion model: constant angular velocity w (rad/s) and constant velocity
//    v (length units/s), both in the camera frame (a car's forward velocity
//    stays forward while it turns): R_{k+1} = Exp(w dt), t_{k+1} = v dt.
//    (The paper writes t'_{k+1} = R(r') t'_k; in the body frame constant
//    velocity needs no rotation, so we keep v.)
//
// Error state (right perturbations on SO(3)): R = R_hat Exp(dtheta), all else
// additive:  [dtheta, dt, dw, dv, dpi_1, ..., dpi_N]   (12 + 3N).
//
// Update: iterated EKF in information form. With prior (x-, P-) and the
// measurements z_j (2D, noise variance s_j^2 I), each Gauss-Newton step solves
//   (P-^-1 + sum_j H_j^T H_j / s_j^2) delta = sum_j H_j^T r_j / s_j^2 - P-^-1 e
// (e = x - x-, r_j = z_j - h_j(x)); the sum runs over macroblocks and each
// term touches only the 6 motion and 3 plane columns, so the cost is linear
// in the number of macroblocks. P+ = (P-^-1 + sum H^T H / s^2)^-1 by LLT.
#pragma once

#include <map>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/common/camera.h"
#include "core/common/rigid3.h"
#include "core/common/status.h"

namespace slapse {

struct EkfOptions {
  // Process noise, per sqrt(second) (random walks).
  double angular_accel_rad_s2 = 0.5;  // change of w
  double relative_accel_per_s = 0.5;  // change of v along its direction, as a fraction of |v|
  // Change of v across its direction, as a fraction of |v|. A camera rigidly
  // mounted on a car sees its direction of travel nearly fixed in its own
  // frame (turning rotates both; only sideslip and pitching move it), so the
  // direction random-walks far less than the speed: 0.2 / sqrt(s) is ~7 deg
  // of direction per 0.4 s step. Isotropic (0.5), three coasting steps let a
  // pair motion 70-90 deg off the travel pass the motion gate (a rural drive
  // at 10 fps whose MVs mostly exceed the search range: ATE 8.7 m -> 1.2 m).
  double lateral_accel_per_s = 0.2;
  // Deviation of one step from constant velocity (vibration, bumps).
  double step_rotation_rad = 0.003;
  double step_translation_rel = 0.05;  // fraction of |t|
  double plane_rel = 1e-3;             // planes are static: tiny, relative to |pi|
  // Added in quadrature to every macroblock's merged-MV variance: the model
  // error of a 16x16 block copy on a plane and the encoder's wrong-but-close
  // matches, px. Lemma 2 alone (0.1-0.2 px) made the filter overconfident on
  // real MVs (on simulated MPEG-2 drives the decoded vectors of plane blocks
  // have a median error of 0.45 px, 60 % within 1 px on the near road):
  // 0.25 px gave eps_D 40-300 % on bench/table2.sh, 1 px 4-80 %.
  double extra_sigma_px = 1.0;
  // Huber threshold on normalised residuals (robust IRLS weights), 0 = off.
  double huber_k = 2.0;
  int iterations = 3;  // Gauss-Newton steps per update (1 = plain EKF)
  // Data association gate: a tracked plane whose correspondences disagree
  // with its prediction (median over its macroblocks of the squared
  // Mahalanobis innovation, 2 dof, against the innovation covariance
  // J P J^T + R) above this is taken for a different surface: the old plane is
  // dropped and the observation starts a new one. 0 = off. (The median of a
  // chi-square with 2 dof is 1.39.)
  double association_gate = 6.0;
  // New planes: inflation of the covariance from their correspondences, and
  // the largest relative standard deviation of |pi| (given the motion) for a
  // plane to be added at all.
  double init_inflation = 4.0;
  double max_init_rel_std = 0.25;
  // Initial uncertainty of the velocities at initialisation.
  double init_angular_velocity_rad_s = 0.2;
  double init_velocity_rel = 0.3;  // fraction of |v|
  // Scale gauge (see Update): planes observed at least this often before an
  // update keep their common scale through it; 0 = off.
  int pin_scale_min_observations = 2;
  // The road (beyond the paper). A car's camera stays at a constant height
  // above one road plane, so the road is the one surface that never leaves
  // the scene, and its pi stays put while the car drives along it
  // (pi^T t ~ 0 in the transition). Plane extraction finds it in about two
  // pairs of three and under a new track id after each gap; as a new plane it
  // would inherit the drifted scale of the moment. Instead the filter keeps
  // one road plane: a plane is road-like when its normal is within
  // road_max_angle_deg of the camera's down axis (+y in C_k) and it lies
  // below the camera; the first road-like plane added becomes the road. It
  // stays in the state for up to road_coast_updates updates without
  // observations (0: removed like any other plane), and a new road-like
  // plane whose normal is within road_reid_max_angle_deg of it and whose
  // distance is within a factor road_reid_max_distance_ratio (the scale may
  // have drifted meanwhile: that is what the observation corrects) is taken
  // as the road seen again. With road_pins_scale, an established road alone
  // pins the scale (see pin_scale_min_observations).
  double road_max_angle_deg = 20.0;
  int road_coast_updates = 45;
  double road_reid_max_angle_deg = 8.0;
  double road_reid_max_distance_ratio = 1.5;
  bool road_pins_scale = true;
  // The car keeps its height above the road: each update adds the
  // pseudo-measurement pi_road^T t = 0 (the step's height change relative to
  // the camera height) with this standard deviation; 0 = off. 0.01: 1.5 cm
  // per step at 1.5 m (bumps, suspension).
  double road_height_rel_sigma = 0.01;
  // Motion measurement (UpdateMotion): the anchor pair's rotation and
  // direction of travel from its epipolar geometry, used where no plane is
  // observed. Standard deviations per axis: bench/motion_accuracy measures
  // 0.06-0.8 deg of rotation and 0.4-6 deg of direction error on the rural
  // and highway tuning drives (with the rare wrong fit the gate refuses).
  double motion_rotation_sigma_rad = 0.008;  // ~0.5 deg
  double motion_direction_sigma_rad = 0.06;  // ~3.4 deg
  // A measurement whose squared Mahalanobis innovation (5 dof) exceeds this
  // is refused (99.9 % of a chi-square with 5 dof: 20.5); 0 = no gate.
  double motion_gate_chi2 = 20.5;
  // The road seen from the frames between the anchors (UpdateRoadStep): a
  // relative standard deviation added to the measured q for the speed's
  // change within the step, and the chi-square gate (1 dof; 99.9 %: 10.83).
  double road_step_rel_sigma = 0.02;
  double road_step_gate_chi2 = 10.83;
  // ... and refused when s differs from its prediction by more than this
  // fraction of it, whatever the covariances say (0 = no such test): a road
  // just added, or coasting long, is uncertain enough to pass the gate with
  // a fit to the wrong surface, and a car's speed does not change that much
  // from one anchor pair to the next.
  double road_step_max_rel_change = 0.25;
  // (Road-like is the one road test of core/common/road.h with down = the
  // camera's +y axis and road_max_angle_deg.)
};

// One plane's macroblock correspondences between the previous anchor and the
// current one.
struct PlaneObservation {
  int track_id = -1;
  std::vector<Eigen::Vector2d> x_later_px;    // in C_k (current anchor)
  std::vector<Eigen::Vector2d> x_earlier_px;  // in C_{k-1}
  std::vector<double> variance_px2;           // merged-MV variance per axis (Lemma 2)
};

struct PlaneTrack {
  int track_id = -1;
  Eigen::Vector3d pi = Eigen::Vector3d::Zero();  // n / d in the current camera frame
  int observations = 0;                          // updates it took part in
  bool road = false;                             // the road plane (EkfOptions)
  int missed_updates = 0;  // consecutive updates without an observation (road only)
  // Kept through the last update without an observation (only the road coasts).
  bool coasting() const { return road && missed_updates > 0; }
};

// The nominal state: step motion, velocities and planes (n / d in C_k).
struct EkfState {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // prev_from_cur rotation of the last step
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // prev_from_cur translation of the last step
  Eigen::Vector3d w = Eigen::Vector3d::Zero();      // angular velocity, rad/s, camera frame
  Eigen::Vector3d v = Eigen::Vector3d::Zero();      // velocity, length units/s, camera frame
  std::vector<Eigen::Vector3d> pis;                 // planes
};

struct UpdateReport {
  int planes_updated = 0, planes_added = 0, planes_removed = 0, planes_rejected = 0;
  int planes_reassociated = 0;  // failed the association gate: replaced by a new plane
  int planes_reidentified = 0;  // new track ids taken as the kept road seen again
  bool road_coasting = false;   // the road is kept without an observation
  int measurements = 0;
  double rms_residual_px = 0.0;  // after the update
  bool skipped = false;          // no tracked plane observed
  // UpdateMotion: the pair's motion was taken (false: not run, or refused by
  // the gate), and its squared Mahalanobis innovation.
  bool motion_updated = false;
  double motion_chi2 = 0.0;
  // UpdateRoadStep: the road seen from the frames between the anchors was
  // taken (false: not run, no road, or refused by a gate), and the squared
  // normalised innovation of its length.
  bool road_step_updated = false;
  double road_step_chi2 = 0.0;
  // AddRoadFromStep: the road joined the filter from the frames.
  bool road_added_from_frames = false;
  // The factor the state's lengths were rescaled by to pin the scale (1: none).
  double scale_correction = 1.0;
};

class PlaneEkf {
 public:
  PlaneEkf(const Intrinsics& intrinsics, EkfOptions options = {});

  // Starts the filter from the first anchor pair's motion (scale fixed by the
  // caller: |t| = 1 up to scale, or metric) and its time gap.
  Status Initialize(const Rigid3d& prev_from_cur, double dt_s);
  bool initialized() const { return initialized_; }

  // Propagates to the next anchor, dt_s after the current one.
  Status Predict(double dt_s);

  // Deletes tracked planes without an observation, updates with the tracked
  // ones (skipped when there are none), then adds untracked ones whose plane
  // is well determined by the updated motion. A numerically failing update
  // leaves the state as predicted and returns INTERNAL.
  Status Update(const std::vector<PlaneObservation>& observations, UpdateReport* report);

  // Updates the step motion with the anchor pair's epipolar motion where no
  // plane constrains it: measured_prev_from_cur's rotation and the direction
  // of its translation (its length is not observed: the step length stays the
  // motion model's). Residual and Jacobian: MotionResidual. Standard EKF
  // update over the whole state (H is zero but for dtheta and t):
  //   S = H P H^T + Q_m,  K = P H^T S^-1 (LLT),  x+ = x (+) K r,
  //   P+ = (I - K H) P (I - K H)^T + K Q_m K^T (Joseph form, symmetrised),
  // with Q_m = diag(sigma_rot^2 I3, sigma_dir^2 I2). A measurement with
  // r^T S^-1 r > motion_gate_chi2 is refused (report->motion_updated false,
  // state unchanged), and so is a direction more than 90 deg off the
  // predicted one (the residual, a sine, shrinks past 90 deg; motion_chi2 is
  // then infinite), and so is an update whose linear step would turn t past
  // the measured direction or away from it (after a taken update, the step's
  // part along t shortens t while it turns, and the turn about doubles).
  // FailedPrecondition before Initialize; InvalidArgument
  // for a non-finite measurement or one without translation; Internal when S
  // is not positive definite.
  Status UpdateMotion(const Rigid3d& measured_prev_from_cur, UpdateReport* report);

  // The kept road's pi in the earlier anchor's camera of the current step
  // (pi_e = R pi / (1 + (R pi)^T t)); nullopt without a road or a step.
  std::optional<Eigen::Vector3d> RoadInEarlierCamera() const;

  // Adds the road seen from the frames between the anchors where the state
  // has none: q = |t| pi_e (core/estimators/road_step.h) with covariance
  // q_cov gives pi_e = q / |t|, carried into the later camera by
  // TransitionPlane; its covariance is J_q (q_cov + (road_step_rel_sigma
  // |q|)^2 I) J_q^T + J_m P_mm J_m^T and
  // its cross-covariance J_m P_mx (m: dtheta, t), so its scale is the
  // trajectory's. It becomes the road (PlaneTrack::road) under `track_id`.
  // False (nothing added) before Initialize, with a road already kept or
  // road_coast_updates = 0, a track id in use, a step without translation,
  // or a plane that is not road-like. Sets report->road_added_from_frames
  // when it adds the road (report may be null).
  bool AddRoadFromStep(const Eigen::Vector3d& q, const Eigen::Matrix3d& q_cov, int track_id,
                       UpdateReport* report = nullptr);

  // Updates the state with the road seen from the frames between the anchors
  // (core/estimators/road_step.h): q = |t| pi_e, of which the filter takes
  // the length s = |t| / d_e (the step length over the road's distance in
  // the earlier anchor's frame), measured with `variance`, predicted as
  // |RoadStepPrediction| from the step and the kept road. With it goes the
  // road-height pseudo-measurement pi^T t = 0 (sigma road_height_rel_sigma,
  // as in Update): a coasting road otherwise drifts through pi^T t, and s
  // would carry the drift into the step length. Standard EKF update over the
  // whole state (S = H P H^T + Q, K by LLT, Joseph form, symmetrised) with
  // Q = diag(variance + (road_step_rel_sigma s)^2, road_height_rel_sigma^2).
  // Refused (report->road_step_updated false, state unchanged) when s's
  // squared normalised innovation exceeds road_step_gate_chi2, when s is
  // more than road_step_max_rel_change off its prediction, or when q's
  // direction is more than road_reid_max_angle_deg off the kept road's (not
  // the road), or when the update would move |t| against s's innovation
  // (s measured shorter, t lengthened: only the state's correlations do
  // that). Taken, it counts as an observation of the road (PinScale's
  // "established" planes). Nothing happens without a road in the state.
  // FailedPrecondition before Initialize; InvalidArgument for a non-finite
  // or zero q or a non-positive variance; Internal when S is not positive
  // definite.
  Status UpdateRoadStep(const Eigen::Vector3d& q, double variance, UpdateReport* report);

  // The filter plane an observation's track id refers to: the id itself, or
  // the kept road's id when that observation's track was re-identified as it.
  int FilterTrackId(int observation_track_id) const;

  // Multiplies every length in the state by `s` (t, v scale by s; pi by 1/s).
  void Rescale(double s);

  Rigid3d prev_from_cur() const { return Rigid3d(R_, t_); }
  const Eigen::Vector3d& angular_velocity_rad_s() const { return w_; }
  const Eigen::Vector3d& velocity_per_s() const { return v_; }
  const std::vector<PlaneTrack>& planes() const { return planes_; }
  // Covariance of the error state (12 + 3N square).
  const Eigen::MatrixXd& covariance() const { return P_; }
  // Covariance block of one plane (3x3), by index into planes().
  Eigen::Matrix3d PlaneCovariance(size_t index) const;

  // --- Model functions, public for the Jacobian tests. ---
  // The motion model applied to a nominal state, and (optionally) its
  // error-state Jacobian F (12 + 3N square): dx_new = F dx_old.
  static EkfState PredictState(const EkfState& state, double dt_s, Eigen::MatrixXd* F);
  // x (+) delta on the error state's manifold (right perturbation on SO(3)).
  static EkfState Retract(const EkfState& state, const Eigen::VectorXd& delta);
  // Plane transition and its Jacobians w.r.t. pi, dtheta (right perturbation
  // of R) and t.
  static Eigen::Vector3d TransitionPlane(const Eigen::Vector3d& pi, const Eigen::Matrix3d& R,
                                         const Eigen::Vector3d& t, Eigen::Matrix3d* d_pi,
                                         Eigen::Matrix3d* d_theta, Eigen::Matrix3d* d_t);
  // Predicted earlier-anchor pixel of later-anchor pixel x and its Jacobians
  // w.r.t. dtheta, t, pi. Returns false when the point maps behind the camera.
  static bool ObservePoint(const Eigen::Matrix3d& K, const Eigen::Matrix3d& K_inv,
                           const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                           const Eigen::Vector3d& pi, const Eigen::Vector2d& x_later,
                           Eigen::Vector2d* x_earlier, Eigen::Matrix<double, 2, 3>* d_theta,
                           Eigen::Matrix<double, 2, 3>* d_t, Eigen::Matrix<double, 2, 3>* d_pi);

  // One plane observation's measurement terms at (R, t, pi), as the update
  // adds them (file comment): with J_j = dz_j / d[dtheta, t, pi] (2 x 9,
  // ObservePoint's), r_j = x_earlier_j - z_j and w_j = h_j / s_j^2 (s_j^2 =
  // variance + extra_sigma_px^2, h_j the Huber weight at huber_k of
  // |r_j| / s_j; huber_k <= 0: none), JtJ = sum_j w_j J_j^T J_j and Jtr =
  // sum_j w_j J_j^T r_j over the MBs ObservePoint accepts (count of them,
  // sq_sum = sum |r_j|^2). Formed through G = K (R + t pi^T), on which z_j
  // depends alone: J_j = A_j D with D = d vec(G) / d[dtheta, t, pi] (9 x 9,
  // columns K R [e_k]x, K e_k pi^T, K t e_k^T) and A_j = dz_j / d vec(G)
  // (rows [p^T / u_z, 0, -u_x p^T / u_z^2] and [0, p^T / u_z, -u_y p^T /
  // u_z^2], u = G p), so per MB only A_j^T A_j's 3 x 3 blocks of p p^T are
  // summed, and JtJ = D^T (sum_j w_j A_j^T A_j) D.
  struct MeasurementSums {
    Eigen::Matrix<double, 9, 9> JtJ = Eigen::Matrix<double, 9, 9>::Zero();
    Eigen::Matrix<double, 9, 1> Jtr = Eigen::Matrix<double, 9, 1>::Zero();
    double sq_sum = 0.0;
    int count = 0;
  };
  static MeasurementSums PlaneMeasurementSums(const Eigen::Matrix3d& K,
                                              const Eigen::Matrix3d& K_inv,
                                              const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                                              const Eigen::Vector3d& pi,
                                              const PlaneObservation& obs, double extra_sigma_px,
                                              double huber_k);

  // The road's height change over a step relative to the height (the
  // road_height_rel_sigma pseudo-measurement, 0 when the step moves along the
  // road): c = pi_road^T t, with dc/dt = pi_road^T and dc/dpi_road = t^T.
  static double RoadHeightChange(const Eigen::Vector3d& pi_road, const Eigen::Vector3d& t,
                                 Eigen::RowVector3d* d_t, Eigen::RowVector3d* d_pi);

  // |t| pi_e (UpdateRoadStep measures its length) predicted from the step
  // (R, t) and the road's pi in the later camera: pi_e = R pi / c with c = 1 +
  // (R pi)^T t (the inverse of TransitionPlane), so with a = R pi
  //   h = |t| a / c,
  //   dh/dt = a t^T / (|t| c) - |t| a a^T / c^2,
  //   dh/dpi = |t| R / c - |t| a t^T R / c^2,
  //   dh/ddtheta = -|t| R [pi]x / c + |t| a t^T R [pi]x / c^2
  // (R = R_hat Exp(dtheta), so da/ddtheta = -R [pi]x).
  static Eigen::Vector3d RoadStepPrediction(const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                                            const Eigen::Vector3d& pi, Eigen::Matrix3d* d_theta,
                                            Eigen::Matrix3d* d_t, Eigen::Matrix3d* d_pi);

  // The motion measurement's prediction error for a step (R, t) against a
  // measured (R_m, u_m = direction of t_m), and (optionally) its Jacobian
  // w.r.t. [dtheta, dt] (R = R_hat Exp(dtheta), t additive):
  //   e = [ Log(R_m^T R) ; B^T t / |t| ]   (5; B = TangentBasis(u_m), core/common/so3.h,
  //                                          so e = 0 at the measurement)
  //   de_rot/ddtheta = Jr(Log(R_m^T R))^-1,   de_dir/dt = B^T (I - u u^T) / |t|,  u = t / |t|.
  static Eigen::Matrix<double, 5, 1> MotionError(const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                                                 const Rigid3d& measured_prev_from_cur,
                                                 Eigen::Matrix<double, 5, 6>* J);

 private:
  static constexpr int kMotionDim = 12;
  int PlaneOffset(size_t index) const { return kMotionDim + 3 * static_cast<int>(index); }
  void RemovePlane(size_t index);
  // The updates' step on the nominal state, in place: x (+) delta as
  // Retract does it (the error state's layout, right perturbation on SO(3)).
  void ApplyErrorStep(const Eigen::VectorXd& delta);
  // P+ = (I - K H) P (I - K H)^T + K Q K^T (Joseph form), symmetrised.
  void JosephCovarianceUpdate(const Eigen::MatrixXd& K, const Eigen::MatrixXd& H,
                              const Eigen::MatrixXd& Q);
  bool AddPlane(const PlaneObservation& obs);
  // The plane of a new observation given the current motion (Gauss-Newton on
  // its transfer errors from the linear least-squares start), with the normal
  // matrix N = sum J_pi^T W J_pi and sum J_pi^T W [J_theta J_t]. False when
  // it is undetermined or behind the camera.
  bool FitNewPlane(const PlaneObservation& obs, Eigen::Vector3d* pi, Eigen::Matrix3d* N,
                   Eigen::Matrix<double, 3, 6>* JtWJm) const;
  bool IsRoadLike(const Eigen::Vector3d& pi) const;
  int RoadIndex() const;  // -1: none

  // Update's steps (see Update). A tracked observation: the index of its
  // plane in planes_ and the observation.
  using TrackedObservation = std::pair<size_t, const PlaneObservation*>;
  struct Association {
    std::vector<TrackedObservation> tracked;         // of planes in the state
    std::vector<const PlaneObservation*> fresh;      // to be added as new planes
    std::set<const PlaneObservation*> reidentified;  // new ids taken as the road
  };
  // Maps observation ids through the road aliases, deletes (or coasts) the
  // planes without an observation and splits the observations.
  Association Associate(const std::vector<PlaneObservation>& observations, UpdateReport* rep);
  void ReidentifyRoad(Association* a, UpdateReport* rep);
  void GateAssociation(Association* a, UpdateReport* rep);
  // Median over the observation's MBs of the squared Mahalanobis innovation
  // against plane `index` (nullopt: no MB).
  std::optional<double> MedianInnovation(size_t index, const PlaneObservation& obs) const;
  // The iterated update with the tracked observations; on success P_ is the
  // posterior and *pi0 holds the planes' prior pi.
  Status IteratedUpdate(const std::vector<TrackedObservation>& tracked, UpdateReport* rep,
                        std::vector<Eigen::Vector3d>* pi0);
  // Adds the MB measurements (and the road-height pseudo-measurement) at the
  // current estimate to the information matrix and right-hand side.
  void AccumulateMeasurements(const std::vector<TrackedObservation>& tracked, Eigen::MatrixXd* info,
                              Eigen::VectorXd* rhs, double* sq_sum, int* count) const;
  void PinScale(const std::vector<TrackedObservation>& tracked,
                const std::vector<Eigen::Vector3d>& pi0, UpdateReport* rep);

  Intrinsics intrinsics_;
  Eigen::Matrix3d K_, K_inv_;
  EkfOptions options_;
  bool initialized_ = false;
  Eigen::Matrix3d R_ = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_ = Eigen::Vector3d::Zero(), w_ = Eigen::Vector3d::Zero(),
                  v_ = Eigen::Vector3d::Zero();
  std::vector<PlaneTrack> planes_;
  Eigen::MatrixXd P_;
  std::map<int, int> road_aliases_;  // observation track id -> the road's track id
};

}  // namespace slapse
