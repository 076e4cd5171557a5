#include "core/estimators/epipolar_plane.h"

#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/LU>

namespace slapse {
namespace {

// Inverse depth of one correspondence along its epipolar line and its weight
// (px per unit of rho, squared); false without epipolar information.
bool InverseDepth(const EpipolarPlanePoint& x, const Eigen::Vector2d& y, double* rho,
                  double* weight) {
  const Eigen::Vector2d g(x.b.x() - y.x() * x.b.z(), x.b.y() - y.y() * x.b.z());
  const Eigen::Vector2d h(y.x() * x.a.z() - x.a.x(), y.y() * x.a.z() - x.a.y());
  const double gg = g.squaredNorm();
  if (!(gg > 1e-18)) return false;
  *rho = g.dot(h) / gg;
  const double p_z = x.a.z() + *rho * x.b.z();
  if (!(std::abs(p_z) > 1e-12)) return false;
  *weight = gg / (p_z * p_z);
  return std::isfinite(*rho) && std::isfinite(*weight);
}

}  // namespace

std::vector<EpipolarPlanePoint> EpipolarPlaneEstimator::Prepare(
    const std::vector<Eigen::Vector2d>& x_later_px, const Intrinsics& intrinsics,
    const Rigid3d& earlier_from_later) {
  const Eigen::Matrix3d K = intrinsics.K();
  const Eigen::Matrix3d KR = K * earlier_from_later.R();
  const Eigen::Vector3d b = K * earlier_from_later.translation;
  std::vector<EpipolarPlanePoint> points(x_later_px.size());
  for (size_t i = 0; i < x_later_px.size(); ++i) {
    points[i].ray_later = intrinsics.Unproject(x_later_px[i]);
    points[i].a = KR * points[i].ray_later;
    points[i].b = b;
  }
  return points;
}

void EpipolarPlaneEstimator::Estimate(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                                      std::vector<M_t>* models) {
  models->clear();
  const size_t n = X.size();
  if (n != Y.size() || n < static_cast<size_t>(kMinNumSamples)) return;
  if (n == static_cast<size_t>(kMinNumSamples)) {
    // r_i^T m = rho_i. With z = 1 rays, det [r_0; r_1; r_2] is twice the area
    // of the triangle of the normalised pixels (times fx fy in px^2). Below
    // 2e-6 -- 1 px^2 at a focal length of 1000 px; MB centres on a 16 px grid
    // give >= 128 px^2 unless collinear -- the sample is degenerate.
    Eigen::Matrix3d A;
    Eigen::Vector3d rhs;
    for (int i = 0; i < 3; ++i) {
      double rho, weight;
      if (!InverseDepth(X[i], Y[i], &rho, &weight)) return;
      A.row(i) = X[i].ray_later.transpose();
      rhs(i) = rho;
    }
    const double det = A.determinant();
    if (!(std::abs(det) > 2e-6)) return;
    models->push_back(A.inverse() * rhs);
    return;
  }
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  int used = 0;
  for (size_t i = 0; i < n; ++i) {
    double rho, weight;
    if (!InverseDepth(X[i], Y[i], &rho, &weight)) continue;
    normal.noalias() += weight * X[i].ray_later * X[i].ray_later.transpose();
    rhs.noalias() += weight * rho * X[i].ray_later;
    ++used;
  }
  if (used < kMinNumSamples) return;
  const Eigen::LLT<Eigen::Matrix3d> llt(normal);
  if (llt.info() != Eigen::Success) return;
  // Rank check: the smallest pivot relative to the largest diagonal entry.
  const Eigen::Vector3d pivots = Eigen::Matrix3d(llt.matrixL()).diagonal();
  if (!(pivots.minCoeff() > 1e-6 * std::sqrt(normal.diagonal().maxCoeff()))) return;
  const Eigen::Vector3d m = llt.solve(rhs);
  if (m.allFinite()) models->push_back(m);
}

void EpipolarPlaneEstimator::Residuals(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                                       const M_t& m, std::vector<double>* squared_residuals) {
  squared_residuals->resize(X.size());
  for (size_t i = 0; i < X.size(); ++i) {
    const double rho = m.dot(X[i].ray_later);
    const Eigen::Vector3d p = X[i].a + rho * X[i].b;
    if (!(rho > 0.0) || !(p.z() > 1e-12)) {
      (*squared_residuals)[i] = std::numeric_limits<double>::infinity();
      continue;
    }
    (*squared_residuals)[i] = (Y[i] - p.head<2>() / p.z()).squaredNorm();
  }
}

Eigen::Matrix3d EpipolarPlaneEstimator::Homography(const M_t& m, const Intrinsics& intrinsics,
                                                   const Rigid3d& earlier_from_later) {
  const Eigen::Matrix3d K = intrinsics.K();
  Eigen::Matrix3d H =
      K * (earlier_from_later.R() + earlier_from_later.translation * m.transpose()) * K.inverse();
  const double norm = H.norm();
  if (norm > 0.0) H /= norm;
  return H;
}

}  // namespace slapse
