// Plane estimator for Ransac<> (core/estimators/ransac.h) when the relative
// camera motion is known up to scale (from the essential matrix): a plane-
// induced homography has then 3 degrees of freedom instead of 8.
//
// Convention: earlier_from_later = (R, t), X_earlier = R X_later + t (the
// translation up to scale, e.g. |t| = 1 from E). A plane of the later camera
// frame, m^T X_later = 1 (m = n / d: unit normal over distance, in the unit
// of t^-1), induces
//   x_earlier ~ H x_later,  H = K (R + t m^T) K^-1,
// the convention of core/planes/plane_extraction.h.
//
// Parameterisation. For the later pixel x with ray r = K^-1 [x; 1] (z = 1),
// the point on the plane is X_later = r / rho with inverse depth rho = m^T r,
// which is linear in m; it projects into the earlier image at
//   p(rho) = a + rho b,  a = K R r,  b = K t,   x_earlier = p_xy / p_z.
// So a plane is an affine function rho(r) = m^T r of the normalised later
// pixel, and fitting planes is fitting that function to per-point inverse
// depths.
//
// Estimate. Each correspondence (x_later, y = x_earlier) gives its inverse
// depth by least squares along its epipolar line: y = (u, v) satisfies
//   rho (b_x - u b_z) = u a_z - a_x,   rho (b_y - v b_z) = v a_z - a_y,
// i.e. rho g = h, rho_i = g.h / g.g. Dividing these equations by p_z turns
// them into pixels, so a change of rho moves the point by about
// |g| / p_z px per unit: the point's weight w_i = g.g / p_z^2. A minimal sample
// (3 points) solves r_i^T m = rho_i exactly; more points solve the weighted
// least squares sum_i w_i (r_i^T m - rho_i)^2 (normal equations, LLT), which
// is the transfer error linearised along the epipolar lines.
// Degenerate (no model): sizes differ, fewer than 3 points, a point without
// epipolar information (g = 0: at the epipole, or a zero translation), a
// minimal sample whose later pixels are (nearly) collinear (normalised
// triangle area below 1e-6, 1 px^2 at f = 1000 px), or a singular normal-equation matrix.
//
// Residuals: the squared transfer error of H, ||y - p_xy / p_z||^2 [px^2],
// +infinity when the point would lie at or beyond infinity (rho = m^T r <= 0)
// or p_z <= 0 -- a plane must lie in front of the camera where it is seen.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/common/camera.h"
#include "core/common/rigid3.h"

namespace slapse {

// A later-anchor point prepared for EpipolarPlaneEstimator.
struct EpipolarPlanePoint {
  Eigen::Vector3d ray_later = Eigen::Vector3d::UnitZ();  // r = K^-1 [x_later; 1]
  Eigen::Vector3d a = Eigen::Vector3d::UnitZ();          // K R r
  Eigen::Vector3d b = Eigen::Vector3d::Zero();           // K t (the same for all points)
};

class EpipolarPlaneEstimator {
 public:
  using X_t = EpipolarPlanePoint;
  using Y_t = Eigen::Vector2d;  // x_earlier, pixels
  using M_t = Eigen::Vector3d;  // m = n / d in the later camera frame

  static constexpr int kMinNumSamples = 3;

  // The points of later pixels `x_later_px` under the given motion.
  static std::vector<EpipolarPlanePoint> Prepare(const std::vector<Eigen::Vector2d>& x_later_px,
                                                 const Intrinsics& intrinsics,
                                                 const Rigid3d& earlier_from_later);

  static void Estimate(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                       std::vector<M_t>* models);

  static void Residuals(const std::vector<X_t>& X, const std::vector<Y_t>& Y, const M_t& m,
                        std::vector<double>* squared_residuals);

  // Ransac<>'s scorer: the points as structure-of-arrays, prepared once per
  // RANSAC call, so that the residuals of a hypothesis are one branch-free
  // pass over contiguous arrays. The same arithmetic as Residuals, in the same
  // order, so the same values.
  class Scorer {
   public:
    Scorer(const std::vector<X_t>& X, const std::vector<Y_t>& Y);
    void Residuals(const M_t& m, std::vector<double>* squared_residuals) const;

   private:
    std::vector<double> rx_, ry_, rz_, ax_, ay_, az_, bx_, by_, bz_, yx_, yy_;
  };

  // H = K (R + t m^T) K^-1 scaled to ||H||_F = 1. Its sign is kept: (H x)_z =
  // p_z > 0 for points in front of the earlier camera, as HomographyEstimator's.
  static Eigen::Matrix3d Homography(const M_t& m, const Intrinsics& intrinsics,
                                    const Rigid3d& earlier_from_later);
};

}  // namespace slapse
