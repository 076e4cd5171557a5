// Planar homography estimator for Ransac<> (core/estimators/ransac.h).
//
// Model and convention: H maps points x of the first image to points y of the
// second, y ~ H x, both in pixel coordinates (homogeneous [u, v, 1]).
// Parameterisation: the 9 entries of H, up to scale; returned models have
// ||H||_F = 1 and the sign for which the third coordinate w = (H x)_z of the
// estimation points is positive (all of them for a minimal sample, the majority
// for a least-squares fit), so that w <= 0 means "mapped through infinity".
//
// Estimate: normalised DLT (Hartley & Zisserman, Alg. 4.2). Each set is
// translated to its centroid and scaled to a mean distance of sqrt(2); H is the
// unit vector h minimising the *algebraic* cost ||A h||^2 of the 2N x 9 system
// from y x (H x) = 0 (right singular vector of the smallest singular value),
// then de-normalised. With N = 4 it is the exact minimal solution, with N > 4
// the algebraic least-squares fit (not the geometric optimum).
// Rejected as degenerate (no model): N < 4, X.size() != Y.size(), coincident
// points, three (nearly) collinear points in either set of a minimal sample, a
// rank-deficient DLT system (e.g. all points on a line), a near-singular H, or
// a minimal sample whose points map to both sides of infinity.
//
// Residuals: squared transfer error in the second image,
//   r_i = ||y_i - dehom(H x_i)||^2  [px^2],
// and +infinity when w = (H x_i)_z <= eps (x_i maps behind / to infinity).
#pragma once

#include <vector>

#include <Eigen/Core>

namespace slapse {

class HomographyEstimator {
 public:
  using X_t = Eigen::Vector2d;
  using Y_t = Eigen::Vector2d;
  using M_t = Eigen::Matrix3d;

  static constexpr int kMinNumSamples = 4;

  static void Estimate(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                       std::vector<M_t>* models);

  static void Residuals(const std::vector<X_t>& X, const std::vector<Y_t>& Y, const M_t& H,
                        std::vector<double>* squared_residuals);
};

}  // namespace slapse
