// Normal equations of many projective transfers through one 3x3 matrix, the
// one home of the trick the window refiner's plane transfer
// (core/refine/plane_transfer_cost.h) and the EKF's update
// (PlaneEkf::PlaneMeasurementSums) share.
//
// Point j has a ray y_j, its image u_j = M y_j under a 3x3 matrix M (a
// homography), the projected pixel scaled per axis, z_j = (s_x u_x / u_z,
// s_y u_y / u_z), a 2-vector e_j and a weight w_j. Its row block of the
// Jacobian with respect to m = vec(M) (row-major, m_{3r+c} = M(r, c)) is
//   A_j = [a y^T, 0, b y^T; 0, c y^T, d y^T],
//   a = s_x / u_z, b = -s_x u_x / u_z^2, c = s_y / u_z, d = -s_y u_y / u_z^2.
// Add sums N = sum_j w_j A_j^T A_j (3 x 3 blocks of y y^T: five distinct,
// N's (0, 1) block is zero) and g = sum_j w_j A_j^T e_j, a few dozen
// operations per point. A caller with M = M(p) then has J^T W J = D^T N D
// and J^T W e = D^T g with D = dm/dp, instead of forming every point's 2 x p
// Jacobian rows and their rank update.
#pragma once

#include <Eigen/Core>

namespace slapse {

class TransferNormalSums {
 public:
  // Point j: y its ray, u = M y (u_z != 0), s_x, s_y the axis scales, e its
  // 2-vector (a residual), w its weight.
  void Add(const Eigen::Vector3d& y, const Eigen::Vector3d& u, double s_x, double s_y,
           const Eigen::Vector2d& e, double w) {
    const double inv_z = 1.0 / u.z();
    const double a = s_x * inv_z, b = -a * u.x() * inv_z;
    const double c = s_y * inv_z, d = -c * u.y() * inv_z;
    const Eigen::Matrix3d yy = y * y.transpose();
    W00_.noalias() += (w * a * a) * yy;
    W02_.noalias() += (w * a * b) * yy;
    W11_.noalias() += (w * c * c) * yy;
    W12_.noalias() += (w * c * d) * yy;
    W22_.noalias() += (w * (b * b + d * d)) * yy;
    g0_.noalias() += (w * a * e.x()) * y;
    g1_.noalias() += (w * c * e.y()) * y;
    g2_.noalias() += (w * (b * e.x() + d * e.y())) * y;
  }

  // N (9 x 9, symmetric) over m's row-major order.
  Eigen::Matrix<double, 9, 9> N() const {
    Eigen::Matrix<double, 9, 9> n = Eigen::Matrix<double, 9, 9>::Zero();
    n.block<3, 3>(0, 0) = W00_;
    n.block<3, 3>(0, 6) = W02_;
    n.block<3, 3>(6, 0) = W02_.transpose();
    n.block<3, 3>(3, 3) = W11_;
    n.block<3, 3>(3, 6) = W12_;
    n.block<3, 3>(6, 3) = W12_.transpose();
    n.block<3, 3>(6, 6) = W22_;
    return n;
  }
  Eigen::Matrix<double, 9, 1> g() const {
    Eigen::Matrix<double, 9, 1> out;
    out << g0_, g1_, g2_;
    return out;
  }

 private:
  Eigen::Matrix3d W00_ = Eigen::Matrix3d::Zero(), W02_ = Eigen::Matrix3d::Zero(),
                  W11_ = Eigen::Matrix3d::Zero(), W12_ = Eigen::Matrix3d::Zero(),
                  W22_ = Eigen::Matrix3d::Zero();
  Eigen::Vector3d g0_ = Eigen::Vector3d::Zero(), g1_ = Eigen::Vector3d::Zero(),
                  g2_ = Eigen::Vector3d::Zero();
};

}  // namespace slapse
