// The window refiner's plane-induced transfer residual (core/refine; one cost
// block per (anchor pair, plane)), in its own header so that its analytic
// Jacobian can be checked against automatic and numeric differentiation
// (refine_test).
//
// Parameter blocks: the earlier anchor's pose (q_a: Eigen quaternion x, y, z,
// w; c_a), the later anchor's pose (q_b, c_b), both world_from_cam, and the
// plane pi_r = n / d in the window's oldest camera r (world_from_r = (R_wr,
// c_wr), constant data):
//   R = R_a^T R_b, t = R_a^T (c_b - c_a)                 (a_from_b)
//   R_rb = R_wr^T R_b, t_rb = R_wr^T (c_b - c_wr)          (r_from_b)
//   pi_b = R_rb^T pi_r / (1 - pi_r^T t_rb)
//   H = R + t pi_b^T;  X_a = H y,  y = K^-1 [x_b; 1]
//   r_j = s_j ([fx X_a.x / X_a.z + cx, fy X_a.y / X_a.z + cy] - x_a)   [px * s_j]
// s_j: the macroblock's weight (inverse sigma times its Huber weight). A
// macroblock with X_a.z <= 1e-9 (behind the earlier camera) makes the block
// fail to evaluate.
//
// Jacobian (PlaneTransferCost): H and dH / d(17 parameters) in closed form
// once per block (plane_transfer_cost.cc; it was forward-mode automatic
// differentiation, ~7x the instructions), then per macroblock the chain rule
// in doubles:
//   dX/dp = sum_k y_k dH_(.,k)/dp,
//   dr_x/dp = s fx (dX.x/dp - (X.x / X.z) dX.z/dp) / X.z   (r_y alike with fy, X.y).
// The Jacobians are with respect to the quaternions' four coordinates (Ceres
// applies the quaternion manifold).
//
// Normal equations (EvaluateNormalEquations, what the refiner's solver uses):
// r_j depends on p only through h = vec(H) (row-major, h_{3r+c} = H(r, c)),
// so J = A D with D = dH/dp (9 x 17, above) and A_j =
// dr_j/dh, whose rows are, with y = y_j, X = X_a, a = s fx / X.z,
// b = -a X.x / X.z, c = s fy / X.z, d = -c X.y / X.z:
//   dr_x/dh = [a y^T, 0, b y^T],   dr_y/dh = [0, c y^T, d y^T].
// Then J^T J = D^T N D and J^T r = D^T G with N = sum_j A_j^T A_j (3 x 3
// blocks of y y^T weighted by a^2, a b, c^2, c d and b^2 + d^2) and
// G = sum_j A_j^T r_j: a few dozen operations per macroblock instead of its
// 2 x 17 Jacobian rows and their 17 x 17 rank update.
#pragma once

#include <vector>

#include <ceres/ceres.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/refine/block_lm.h"

namespace slapse {

struct PlaneTransferData {
  struct Mb {
    Eigen::Vector3d ray;  // K^-1 [x_later; 1]
    Eigen::Vector2d x_earlier;
    double scale = 1.0;  // s_j
  };
  std::vector<Mb> mbs;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Eigen::Matrix3d R_rw = Eigen::Matrix3d::Identity();  // R_wr^T
  Eigen::Vector3d c_wr = Eigen::Vector3d::Zero();

  // H (a_from_b's plane-induced homography on normalised rays).
  template <typename T>
  Eigen::Matrix<T, 3, 3> Homography(const T* q_a, const T* c_a, const T* q_b, const T* c_b,
                                    const T* pi_r) const {
    using Vec3 = Eigen::Matrix<T, 3, 1>;
    using Mat3 = Eigen::Matrix<T, 3, 3>;
    const Eigen::Map<const Eigen::Quaternion<T>> qa(q_a), qb(q_b);
    const Eigen::Map<const Vec3> ca(c_a), cb(c_b), pir(pi_r);
    const Mat3 Ra = qa.toRotationMatrix(), Rb = qb.toRotationMatrix();
    const Vec3 t = Ra.transpose() * (cb - ca);
    const Mat3 R_rb = R_rw.cast<T>() * Rb;
    const Vec3 t_rb = R_rw.cast<T>() * (cb - c_wr.cast<T>());
    const Vec3 pi_b = R_rb.transpose() * pir / (T(1.0) - pir.dot(t_rb));
    return Ra.transpose() * Rb + t * pi_b.transpose();
  }

  // The macroblock's residual r_j under H (px * s_j); false when X_a.z <=
  // 1e-9 (behind the earlier camera). The one home of the transfer: the
  // cost, its autodiff reference and the refiner's Huber weights use it.
  template <typename T>
  bool Residual(const Eigen::Matrix<T, 3, 3>& H, const Mb& mb, T* r) const {
    const Eigen::Matrix<T, 3, 1> X = H * mb.ray.cast<T>();
    if (!(X.z() > T(1e-9))) return false;
    const T inv_z = T(1.0) / X.z();
    r[0] = (T(fx) * X.x() * inv_z + T(cx - mb.x_earlier.x())) * T(mb.scale);
    r[1] = (T(fy) * X.y() * inv_z + T(cy - mb.x_earlier.y())) * T(mb.scale);
    return true;
  }
};

// The residual for ceres::AutoDiffCostFunction: the reference the analytic
// Jacobian is tested against (refine_test).
struct PlaneTransferResidual {
  template <typename T>
  bool operator()(const T* q_a, const T* c_a, const T* q_b, const T* c_b, const T* pi_r,
                  T* residual) const {
    const Eigen::Matrix<T, 3, 3> H = data.Homography(q_a, c_a, q_b, c_b, pi_r);
    for (size_t j = 0; j < data.mbs.size(); ++j) {
      if (!data.Residual(H, data.mbs[j], residual + 2 * j)) return false;
    }
    return true;
  }
  PlaneTransferData data;
};

// The same residual with the Jacobian and the normal equations of the header.
class PlaneTransferCost : public NormalEquationsCost {
 public:
  explicit PlaneTransferCost(PlaneTransferData data);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;
  bool EvaluateNormalEquations(double const* const* parameters, double* half_squared_norm,
                               Eigen::VectorXd* gradient, Eigen::MatrixXd* normal) const override;

 private:
  using HomographyJacobian = Eigen::Matrix<double, 9, 17, Eigen::RowMajor>;
  // H and dH/dp (row 3 r + c: H(r, c)'s gradient over the 17 parameters).
  void HomographyAndJacobian(double const* const* parameters, Eigen::Matrix3d* H,
                             HomographyJacobian* dH) const;

  PlaneTransferData data_;
};

}  // namespace slapse
