#include "core/estimators/relative_pose.h"

#include <cmath>
#include <limits>

#include <Eigen/Cholesky>

#include "core/common/so3.h"

namespace slapse {
namespace {

// Sampson distances of every correspondence under E, into *r.
void AllResiduals(const std::vector<Eigen::Vector3d>& rays_earlier,
                  const std::vector<Eigen::Vector3d>& rays_later, const Eigen::Matrix3d& E,
                  std::vector<double>* r) {
  r->resize(rays_earlier.size());
  for (size_t i = 0; i < rays_earlier.size(); ++i) {
    (*r)[i] = SampsonDistance(E, rays_earlier[i], rays_later[i]);
  }
}

// Sum of r_i^2 over the points of `mask`.
double MaskedCost(const std::vector<double>& r, const std::vector<char>& mask) {
  double cost = 0.0;
  for (size_t i = 0; i < mask.size(); ++i) {
    if (mask[i]) cost += r[i] * r[i];
  }
  return cost;
}

}  // namespace

double SampsonDistance(const Eigen::Matrix3d& E, const Eigen::Vector3d& ray_earlier,
                       const Eigen::Vector3d& ray_later, Eigen::Matrix<double, 1, 9>* d_r_d_E) {
  // a = E x_e, b = E^T x_l, e = x_l^T a, D = a_0^2 + a_1^2 + b_0^2 + b_1^2.
  const Eigen::Vector3d a = E * ray_earlier;
  const Eigen::Vector3d b = E.transpose() * ray_later;
  const double e = ray_later.dot(a);
  const double D = a(0) * a(0) + a(1) * a(1) + b(0) * b(0) + b(1) * b(1);
  if (!(D > 1e-300)) {
    if (d_r_d_E != nullptr) d_r_d_E->setZero();
    return std::numeric_limits<double>::infinity();
  }
  const double inv_sqrt_D = 1.0 / std::sqrt(D);
  const double r = e * inv_sqrt_D;
  if (d_r_d_E != nullptr) {
    // de/dE_ij = x_l,i x_e,j;  dD/dE_ij = 2 a_i x_e,j [i < 2] + 2 b_j x_l,i [j < 2];
    // dr = de / sqrt(D) - e dD / (2 D^(3/2)) = (de - r dD / (2 sqrt(D))) / sqrt(D).
    const double half_r_over_sqrt_D = r * inv_sqrt_D;  // r / sqrt(D); dD carries the 2
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        double dD_half = 0.0;
        if (i < 2) dD_half += a(i) * ray_earlier(j);
        if (j < 2) dD_half += b(j) * ray_later(i);
        (*d_r_d_E)(3 * i + j) =
            (ray_later(i) * ray_earlier(j) - half_r_over_sqrt_D * dD_half) * inv_sqrt_D;
      }
    }
  }
  return r;
}

Eigen::Matrix<double, 9, 5> EssentialJacobian(const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                                              const Eigen::Matrix<double, 3, 2>& basis) {
  Eigen::Matrix<double, 9, 5> J;
  const Eigen::Matrix3d t_x_R = Skew(t) * R;
  for (int k = 0; k < 5; ++k) {
    const Eigen::Matrix3d dE = k < 3 ? Eigen::Matrix3d(t_x_R * Skew(Eigen::Vector3d::Unit(k)))
                                     : Eigen::Matrix3d(Skew(basis.col(k - 3)) * R);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) J(3 * i + j, k) = dE(i, j);
    }
  }
  return J;
}

namespace {

// One Levenberg-Marquardt step on sum r_i^2 over the selected points: the
// Gauss-Newton system H = sum J^T J, g = sum J^T r with J = dr/dE dE/d(theta,
// delta), damped (A = H + lambda diag(H)) until the step lowers the cost, up
// to 6 times. True when a step was taken (R, t and lambda updated).
// *residuals holds every point's Sampson distance under (R, t) on entry and
// on return: a candidate's distances are computed for all points, so an
// accepted step leaves those the next re-selection needs.
bool LevenbergMarquardtStep(const std::vector<Eigen::Vector3d>& rays_earlier,
                            const std::vector<Eigen::Vector3d>& rays_later,
                            const std::vector<char>& selected, Eigen::Matrix3d* R_io,
                            Eigen::Vector3d* t_io, double* lambda_io,
                            std::vector<double>* residuals, std::vector<double>* scratch) {
  Eigen::Matrix3d& R = *R_io;
  Eigen::Vector3d& t = *t_io;
  double& lambda = *lambda_io;
  const size_t n = rays_earlier.size();
  const Eigen::Matrix<double, 3, 2> basis = TangentBasis(t);
  const Eigen::Matrix<double, 9, 5> dE_dp = EssentialJacobian(R, t, basis);
  const Eigen::Matrix3d E_now = Skew(t) * R;
  Eigen::Matrix<double, 5, 5> H = Eigen::Matrix<double, 5, 5>::Zero();
  Eigen::Matrix<double, 5, 1> g = Eigen::Matrix<double, 5, 1>::Zero();
  Eigen::Matrix<double, 1, 9> d_r_d_E;
  for (size_t i = 0; i < n; ++i) {
    if (!selected[i]) continue;
    const double r = SampsonDistance(E_now, rays_earlier[i], rays_later[i], &d_r_d_E);
    const Eigen::Matrix<double, 1, 5> J = d_r_d_E * dE_dp;
    H.noalias() += J.transpose() * J;
    g.noalias() += J.transpose() * r;
  }
  const double cost = MaskedCost(*residuals, selected);
  for (int attempt = 0; attempt < 6; ++attempt) {
    Eigen::Matrix<double, 5, 5> A = H;
    A.diagonal() += lambda * H.diagonal() + Eigen::Matrix<double, 5, 1>::Constant(1e-15);
    const Eigen::Matrix<double, 5, 1> delta = A.ldlt().solve(-g);
    if (!delta.allFinite()) return false;
    const Eigen::Matrix3d R_new = R * ExpSO3(delta.head<3>());
    const Eigen::Vector3d t_new = (t + basis * delta.tail<2>()).normalized();
    AllResiduals(rays_earlier, rays_later, Eigen::Matrix3d(Skew(t_new) * R_new), scratch);
    const double new_cost = MaskedCost(*scratch, selected);
    if (new_cost < cost) {
      R = R_new;
      t = t_new;
      residuals->swap(*scratch);
      lambda = std::max(1e-10, 0.1 * lambda);
      return true;
    }
    lambda *= 10.0;
  }
  return false;
}

}  // namespace

RelativePoseRefineReport RefineRelativePose(const std::vector<Eigen::Vector3d>& rays_earlier,
                                            const std::vector<Eigen::Vector3d>& rays_later,
                                            const Rigid3d& initial_later_from_earlier,
                                            const RelativePoseRefineOptions& options) {
  RelativePoseRefineReport report;
  report.later_from_earlier = initial_later_from_earlier;
  const size_t n = rays_earlier.size();
  if (n != rays_later.size() || !(options.max_error > 0.0) ||
      !(initial_later_from_earlier.translation.norm() > 0.0)) {
    return report;
  }
  Eigen::Matrix3d R = initial_later_from_earlier.R();
  Eigen::Vector3d t = initial_later_from_earlier.translation.normalized();
  constexpr int kMinInliers = 5;
  constexpr double kWideningMultipliers[] = {3.0, 2.0, 1.5};
  const int num_stages = 3 + std::max(1, options.max_final_stages);

  std::vector<char> selected(n, 0), previous(n, 0);
  // Every point's Sampson distance under the current (R, t), kept current by
  // the steps.
  std::vector<double> residuals, scratch;
  AllResiduals(rays_earlier, rays_later, Eigen::Matrix3d(Skew(t) * R), &residuals);
  for (int stage = 0; stage < num_stages; ++stage) {
    const double threshold = options.max_error * (stage < 3 ? kWideningMultipliers[stage] : 1.0);
    int count = 0;
    for (size_t i = 0; i < n; ++i) {
      selected[i] = std::abs(residuals[i]) <= threshold;
      count += selected[i];
    }
    if (count < kMinInliers) return report;
    // At max_error, a stable inlier set ends the refinement.
    if (stage > 3 && selected == previous) break;
    previous = selected;

    double lambda = 1e-4;
    for (int step = 0; step < options.steps_per_stage; ++step) {
      // At a minimum of this stage's cost: no step is accepted.
      if (!LevenbergMarquardtStep(rays_earlier, rays_later, selected, &R, &t, &lambda, &residuals,
                                  &scratch)) {
        break;
      }
    }
  }
  if (!R.allFinite() || !t.allFinite()) return report;

  report.inlier_mask.assign(n, 0);
  for (size_t i = 0; i < n; ++i) {
    report.inlier_mask[i] = std::abs(residuals[i]) <= options.max_error;
    report.num_inliers += report.inlier_mask[i];
  }
  if (report.num_inliers < kMinInliers) {
    report.inlier_mask.clear();
    report.num_inliers = 0;
    return report;
  }
  report.success = true;
  // Re-orthonormalised by Rigid3d (products of Exp steps drift by rounding only).
  report.later_from_earlier = Rigid3d(R, t);
  return report;
}

int CountCheirality(const std::vector<Eigen::Vector3d>& rays_earlier,
                    const std::vector<Eigen::Vector3d>& rays_later,
                    const Rigid3d& later_from_earlier, const std::vector<char>& mask,
                    double max_depth) {
  const Eigen::Matrix3d R = later_from_earlier.R();
  const Eigen::Vector3d& t = later_from_earlier.translation;
  int count = 0;
  for (size_t i = 0; i < rays_earlier.size(); ++i) {
    if (!mask.empty() && !mask[i]) continue;
    // The point X = (z x_e, w) on the earlier ray (homogeneous, earlier
    // camera's frame). The later image point (x1, y1) = x_l / x_l.z gives
    // the linear-triangulation rows
    //   x1 (R X)_3 - (R X)_1 = a1 z + b1 w = 0,  y1 (R X)_3 - (R X)_2 = a2 z + b2 w = 0,
    // solved for (z, w) in least squares with |X| = 1: with z' = z |x_e|, the
    // smallest eigenvector of the 2x2 Gram matrix G of [a / |x_e|, b].
    const Eigen::Vector3d& x_e = rays_earlier[i];
    const Eigen::Vector3d u = R * x_e;
    const double x1 = rays_later[i].x() / rays_later[i].z();
    const double y1 = rays_later[i].y() / rays_later[i].z();
    const double norm_e = x_e.norm();
    const double a1 = (x1 * u.z() - u.x()) / norm_e, b1 = x1 * t.z() - t.x();
    const double a2 = (y1 * u.z() - u.y()) / norm_e, b2 = y1 * t.z() - t.y();
    const double g11 = a1 * a1 + a2 * a2, g12 = a1 * b1 + a2 * b2, g22 = b1 * b1 + b2 * b2;
    const double lambda_min =
        0.5 * (g11 + g22 - std::sqrt((g11 - g22) * (g11 - g22) + 4.0 * g12 * g12));
    // Two expressions of the eigenvector; the longer is the better conditioned.
    double z = g12, w = lambda_min - g11;
    if (std::abs(lambda_min - g22) + std::abs(g12) > std::abs(z) + std::abs(w)) {
      z = lambda_min - g22;
      w = g12;
    }
    z /= norm_e;
    // In front of the earlier camera (depth z x_e.z / w > 0) and of the later one.
    if (!(z * w * x_e.z() > 0.0)) continue;
    const double ray_depth = z / w;
    const double depth_e = ray_depth * x_e.z();
    const double depth_l = (ray_depth * u + t).z();
    if (depth_e < max_depth && depth_l > 0.0 && depth_l < max_depth) ++count;
  }
  return count;
}

}  // namespace slapse
