// The pose of one decoded frame from its own motion vectors against known
// planes (docs/METHOD.md "Per-frame poses").
//
// Between two tracked anchors every other frame (B frames, and the P frames
// inside a chained IPPP pair) has motion vectors into a frame whose pose and
// planes are known (an anchor, or the previous frame). A vector of a block
// with centre x in frame f says the block's content is at p = x + d in its
// reference r. When p lies on a known plane (n . X = d_w in the world), the
// ray of p from r's camera meets it in a world point X_w, and x is where X_w
// projects into f. Each such vector is one observation (X_w, x, sigma^2);
// this file estimates world_from_cam of f from them.
//
// Cost (MAP with a pose prior), over observations j:
//   E(T) = sum_j rho(|r_j|^2 / s_j^2) + e_p^T P_p^-1 e_p
//   r_j  = pi(K R^T (X_w,j - t)) - x_j                (pixels)
//   s_j^2 = variance_px2_j + extra_sigma_px^2
// rho: Huber on the normalised residual (threshold huber_k); e_p = the pose's
// difference to the prior pose (the anchors' interpolation) on the same
// manifold as the update, P_p = diag(sigma_rot^2 I, sigma_pos^2 I).
//
// Parameterisation: T = world_from_cam = (R, t) (x_world = R x_cam + t),
// perturbed as R = R_hat Exp(dtheta), t = t_hat + dt; delta = [dtheta, dt].
// With X_c = R^T (X_w - t):
//   X_c(delta) ~ X_c + [X_c]_x dtheta - R_hat^T dt
// so dX_c/dtheta = [X_c]_x, dX_c/dt = -R_hat^T, and with
//   dpi/dX_c = [fx/z, 0, -fx x/z^2; 0, fy/z, -fy y/z^2]
// the residual's Jacobian is J = dpi/dX_c [ [X_c]_x, -R_hat^T ]  (2 x 6).
// Gauss-Newton (IRLS for the Huber weights) solves
//   (sum w_j J_j^T J_j / s_j^2 + P_p^-1) delta = -(sum w_j J_j^T r_j / s_j^2 + P_p^-1 e_p).
// The covariance reported is the inverse of that normal matrix at the
// solution (anchors and planes held fixed: it is relative to them).
//
// Degenerate input is "no model" (nullopt, with the reason in the report):
// fewer than min_inliers observations within inlier_sigmas after the fit, or
// the data alone (without the prior) not constraining all six directions.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/camera.h"
#include "core/common/rigid3.h"
#include "core/common/status.h"

namespace slapse {

struct FramePoseOptions {
  int max_iterations = 8;
  // Added in quadrature to every vector's variance (block-copy model error,
  // as EkfOptions::extra_sigma_px), px.
  double extra_sigma_px = 1.0;
  double huber_k = 2.0;        // robust threshold on normalised residuals
  double inlier_sigmas = 3.0;  // an observation is an inlier within this many sigmas
  int min_inliers = 20;        // fewer: no model
  // The prior (interpolated pose): standard deviations; <= 0 turns that part off.
  // Chosen on tuning seeds 1-3 (docs/TRAJECTORY.md "Per-frame poses"): between
  // two anchors a car's position follows the interpolation to 2-4 mm, far
  // closer than one frame's vectors place it (~1 cm), while its rotation
  // (vibration) does not: the vectors mostly correct the rotation.
  double prior_rotation_rad = 0.01;
  double prior_position_rel = 0.002;  // fraction of the anchors' step length
  // The data's information in its weakest direction must reach this share of
  // its strongest (translation scaled by the typical depth), else no model.
  double min_information_ratio = 1e-8;
  // Stop when |delta| (rad, length) falls below this. 1e-4 (0.006 deg; a
  // tenth of a mm at metric scale) is far below what one frame's vectors
  // resolve. 1e-6 -> 1e-4 in session 35: EstimateFramePose 0.67 -> 0.47 G
  // instructions on the camera stream (5.3 Gauss-Newton passes per frame
  // before; docs/BENCHMARKS.md "Session 35"); the anchors' poses unchanged,
  // every tuning drive's ATE within 1e-5 percentage points.
  double step_tolerance = 1e-4;

  // InvalidArgument unless iterations >= 1, sigmas / thresholds > 0, min_inliers >= 6,
  // prior sigmas finite, ratio in [0, 1).
  Status Check(const std::string& who = "FramePoseOptions") const;
};

// One motion vector of the frame on a known plane.
struct FramePoseObservation {
  Eigen::Vector3d point_world = Eigen::Vector3d::Zero();  // X_w on its plane
  Eigen::Vector2d x_px = Eigen::Vector2d::Zero();         // block centre in the frame
  double variance_px2 = 0.0;                              // vector error per axis
};

struct FramePoseReport {
  int observations = 0;
  int inliers = 0;      // within inlier_sigmas at the solution
  double rms_px = 0.0;  // over the inliers
  int iterations = 0;
  // [dtheta, dt] of world_from_cam (right rotation perturbation), given the
  // anchors and planes: rad^2 and length^2.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  double position_sigma = 0.0;  // sqrt(trace of the dt block)
  std::string no_model_reason;  // set when the estimate returned nothing
};

// Residual r = pi(K R^T (X_w - t)) - x and (optionally) its Jacobian w.r.t.
// delta = [dtheta, dt] (see above). False when X_w is not in front of the camera.
bool FramePoseResidual(const Intrinsics& intrinsics, const Rigid3d& world_from_cam,
                       const FramePoseObservation& obs, Eigen::Vector2d* residual,
                       Eigen::Matrix<double, 2, 6>* jacobian);

// T (+) delta on the parameterisation above.
Rigid3d RetractFramePose(const Rigid3d& world_from_cam, const Eigen::Matrix<double, 6, 1>& delta);

// The frame's pose from `observations`, starting at (and, with prior sigmas,
// pulled towards) `prior_world_from_cam`; `step_length` is the distance
// between the two anchors around the frame (the prior's position unit).
// nullopt: no model (the report says why).
std::optional<Rigid3d> EstimateFramePose(const Intrinsics& intrinsics,
                                         const std::vector<FramePoseObservation>& observations,
                                         const Rigid3d& prior_world_from_cam, double step_length,
                                         const FramePoseOptions& options, FramePoseReport* report);

}  // namespace slapse
