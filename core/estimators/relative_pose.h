// Local refinement of a relative camera pose (essential matrix) from a nearby
// initial guess -- e.g. the previous anchor pair's motion, which changes slowly
// from pair to pair -- instead of a full robust search.
//
// Convention: later_from_earlier = (R, t), X_later = R X_earlier + t, |t| = 1
// (up to scale). Correspondences are rays on the normalised image planes
// (z = 1): x_e = K^-1 [x_earlier_px; 1], x_l = K^-1 [x_later_px; 1]. The
// epipolar constraint is x_l^T E x_e = 0 with E = [t]x R.
//
// Residual: the signed Sampson distance (first-order geometric distance to
// the epipolar manifold, normalised image units)
//   r = x_l^T E x_e / sqrt((E x_e)_0^2 + (E x_e)_1^2 + (E^T x_l)_0^2 + (E^T x_l)_1^2),
// which times the focal length is about the pixel distance (as OpenCV's
// essential-matrix RANSAC scores it).
//
// Parameters: 5 DOF around the current (R, t). Rotation perturbed on the right,
// R(theta) = R Exp(theta) (core/common/so3.h); translation on the unit sphere,
// t(delta) = normalize(t + B delta) with B = [b_0 b_1] an orthonormal basis of
// the plane orthogonal to t. At theta = delta = 0:
//   dE/dtheta_k = [t]x R [e_k]x,   dE/ddelta_j = [b_j]x R.
// The chain rule with dr/dE gives the 1x5 Jacobian of each residual.
//
// Refinement (RefineRelativePose): robust by re-selection, as LO-RANSAC: at
// thresholds 3, 2, 1.5 x max_error and then max_error until the inlier set is
// stable, the inliers of the current pose are selected and the pose takes
// Levenberg-Marquardt steps minimising sum r_i^2 over them. The widening start
// lets a guess that is off by more than max_error on part of the image (the
// previous pair's motion) collect its true inliers. The result is a local
// optimum near the guess: callers must check that it explains the data (e.g.
// its inlier count against a full robust fit's) before trusting it.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/common/rigid3.h"

namespace slapse {

struct RelativePoseRefineOptions {
  // Inlier threshold on |Sampson distance|, normalised image units (pixels
  // divided by the focal length); > 0.
  double max_error = 0.0;
  // Re-selection stages at max_error after the three widening ones.
  int max_final_stages = 5;
  // Levenberg-Marquardt steps per stage.
  int steps_per_stage = 1;
};

struct RelativePoseRefineReport {
  bool success = false;           // false: fewer than 5 inliers at some stage, or a non-finite pose
  Rigid3d later_from_earlier;     // |t| = 1; the initial guess when !success
  std::vector<char> inlier_mask;  // |r_i| <= max_error under the final pose (empty if !success)
  int num_inliers = 0;
};

// Signed Sampson distance of one correspondence under E, and (if non-null) its
// gradient with respect to E's entries in row-major order (dr/dE_00, dr/dE_01,
// ...). +infinity (gradient zero) when the denominator vanishes.
double SampsonDistance(const Eigen::Matrix3d& E, const Eigen::Vector3d& ray_earlier,
                       const Eigen::Vector3d& ray_later,
                       Eigen::Matrix<double, 1, 9>* d_r_d_E = nullptr);

// dE/d(theta, delta) at (R, t), row-major vec(E) per column (see file comment);
// `basis` = [b_0 b_1] (3x2, orthonormal, orthogonal to t).
Eigen::Matrix<double, 9, 5> EssentialJacobian(const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                                              const Eigen::Matrix<double, 3, 2>& basis);

// Refines `initial_later_from_earlier` (its t is normalised; |t| > 0 needed)
// on the rays. Deterministic.
RelativePoseRefineReport RefineRelativePose(const std::vector<Eigen::Vector3d>& rays_earlier,
                                            const std::vector<Eigen::Vector3d>& rays_later,
                                            const Rigid3d& initial_later_from_earlier,
                                            const RelativePoseRefineOptions& options);

// Points of `mask` (all when empty) triangulated in front of both cameras and
// nearer than max_depth (in units of |t| = 1) in both. The cheirality test of
// cv::recoverPose (which uses max_depth = 50), with the same linear
// triangulation (the homogeneous least squares of the two views' image
// equations, |X| = 1) restricted to the earlier ray, which leaves a 2x2
// problem in closed form instead of a 4x4 SVD per point. Points without
// parallax come out near infinity (w ~ 0) and are not counted; a least-squares
// fit of the depths along both rays had instead placed ~4 % of a pure
// rotation's noisy points in front within the bound (relative_pose_test).
int CountCheirality(const std::vector<Eigen::Vector3d>& rays_earlier,
                    const std::vector<Eigen::Vector3d>& rays_later,
                    const Rigid3d& later_from_earlier, const std::vector<char>& mask,
                    double max_depth = 50.0);

}  // namespace slapse
