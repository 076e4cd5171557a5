// SO(3) helpers: hat/skew, exponential and logarithm maps, right Jacobian.
// Perturbations in slapse are right-multiplied: R = R_hat * Exp(dtheta).
#pragma once

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace slapse {

inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

inline Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-12) return Eigen::Matrix3d::Identity() + Skew(w);
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

inline Eigen::Vector3d LogSO3(const Eigen::Matrix3d& r) {
  const Eigen::AngleAxisd aa(r);
  return aa.angle() * aa.axis();
}

// Right Jacobian: Exp(w + dw) ~= Exp(w) * Exp(Jr(w) dw).
inline Eigen::Matrix3d RightJacobianSO3(const Eigen::Vector3d& w) {
  const double a = w.norm();
  const Eigen::Matrix3d s = Skew(w);
  if (a < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * s;
  return Eigen::Matrix3d::Identity() - (1 - std::cos(a)) / (a * a) * s +
         (a - std::sin(a)) / (a * a * a) * s * s;
}

// An orthonormal basis [b_0 b_1] (3x2) of the plane orthogonal to the unit
// vector t (the tangent space of the unit sphere at t).
inline Eigen::Matrix<double, 3, 2> TangentBasis(const Eigen::Vector3d& t) {
  // The axis least aligned with t gives a well-conditioned cross product.
  Eigen::Vector3d::Index axis;
  t.cwiseAbs().minCoeff(&axis);
  const Eigen::Vector3d b0 = t.cross(Eigen::Vector3d::Unit(axis)).normalized();
  Eigen::Matrix<double, 3, 2> basis;
  basis.col(0) = b0;
  basis.col(1) = t.cross(b0).normalized();
  return basis;
}

}  // namespace slapse
