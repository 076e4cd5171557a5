#include "core/estimators/epipolar_plane.h"

#include <algorithm>
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

EpipolarPlaneEstimator::Scorer::Scorer(const std::vector<X_t>& X, const std::vector<Y_t>& Y) {
  const size_t n = std::min(X.size(), Y.size());
  for (std::vector<double>* a :
       {&rx_, &ry_, &rz_, &ax_, &ay_, &az_, &bx_, &by_, &bz_, &yx_, &yy_}) {
    a->resize(n);
  }
  for (size_t i = 0; i < n; ++i) {
    rx_[i] = X[i].ray_later.x();
    ry_[i] = X[i].ray_later.y();
    rz_[i] = X[i].ray_later.z();
    ax_[i] = X[i].a.x();
    ay_[i] = X[i].a.y();
    az_[i] = X[i].a.z();
    bx_[i] = X[i].b.x();
    by_[i] = X[i].b.y();
    bz_[i] = X[i].b.z();
    yx_[i] = Y[i].x();
    yy_[i] = Y[i].y();
  }
}

void EpipolarPlaneEstimator::Scorer::Residuals(const M_t& m,
                                               std::vector<double>* squared_residuals) const {
  const size_t n = rx_.size();
  squared_residuals->resize(n);
  double* out = squared_residuals->data();
  const double mx = m.x(), my = m.y(), mz = m.z();
  constexpr double kInfinity = std::numeric_limits<double>::infinity();
  // As Residuals, operation for operation: rho = m . r (Eigen's order of the
  // sum), p = a + rho b, r^2 = |y - p_xy / p_z|^2; +infinity unless rho > 0
  // and p_z > 1e-12. Two points at a time in Eigen's fixed-size packets (the
  // two divisions dominate; SIMD halves them), the validity test per point.
  using Pair = Eigen::Array2d;
  auto at = [](const std::vector<double>& v, size_t i) { return Eigen::Map<const Pair>(&v[i]); };
  size_t i = 0;
  for (; i + 2 <= n; i += 2) {
    const Pair rho = mx * at(rx_, i) + (my * at(ry_, i) + mz * at(rz_, i));
    const Pair pz = at(az_, i) + rho * at(bz_, i);
    const Pair dx = at(yx_, i) - (at(ax_, i) + rho * at(bx_, i)) / pz;
    const Pair dy = at(yy_, i) - (at(ay_, i) + rho * at(by_, i)) / pz;
    const Pair sq = dx * dx + dy * dy;
    out[i] = rho(0) > 0.0 && pz(0) > 1e-12 ? sq(0) : kInfinity;
    out[i + 1] = rho(1) > 0.0 && pz(1) > 1e-12 ? sq(1) : kInfinity;
  }
  for (; i < n; ++i) {
    const double rho = mx * rx_[i] + (my * ry_[i] + mz * rz_[i]);
    const double pz = az_[i] + rho * bz_[i];
    const double dx = yx_[i] - (ax_[i] + rho * bx_[i]) / pz;
    const double dy = yy_[i] - (ay_[i] + rho * by_[i]) / pz;
    out[i] = rho > 0.0 && pz > 1e-12 ? dx * dx + dy * dy : kInfinity;
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
