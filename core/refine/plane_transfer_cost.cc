#include "core/refine/plane_transfer_cost.h"

#include <utility>

#include "core/common/transfer_normal_sums.h"

namespace slapse {
namespace {

constexpr int kBlockSizes[5] = {4, 3, 4, 3, 3};  // q_a, c_a, q_b, c_b, pi_r
constexpr int kNumParameters = 17;

// dR/dq_i (i = x, y, z, w) of Eigen's Quaternion::toRotationMatrix (the
// formula as written, which does not normalise q): each entry is linear in q.
void RotationJacobian(const double* q, Eigen::Matrix3d dR[4]) {
  const double x = 2 * q[0], y = 2 * q[1], z = 2 * q[2], w = 2 * q[3];
  dR[0] << 0, y, z, y, -2 * x, -w, z, w, -2 * x;
  dR[1] << -2 * y, x, w, x, 0, z, -w, z, -2 * y;
  dR[2] << -2 * z, -w, x, w, -2 * z, y, x, y, 0;
  dR[3] << 0, -z, y, z, 0, -x, -y, x, 0;
}

}  // namespace

PlaneTransferCost::PlaneTransferCost(PlaneTransferData data) : data_(std::move(data)) {
  set_num_residuals(2 * static_cast<int>(data_.mbs.size()));
  for (int size : kBlockSizes) mutable_parameter_block_sizes()->push_back(size);
}

// With u = R_rw^T pi_r, s = 1 - u . (c_b - c_wr), d = c_b - c_a, the
// header's H is Ra^T Rb + t pi_b^T with t = Ra^T d and pi_b = Rb^T u / s.
// Its derivatives (3 x 3 each, e_k the k-th unit vector, dR_i = dR/dq_i):
//   q_a,i:  dRa_i^T (Rb + d pi_b^T)
//   c_a,k:  -Ra^T e_k pi_b^T
//   q_b,i:  (Ra^T + t u^T / s) dRb_i
//   c_b,k:  (Ra^T e_k + t u_k / s) pi_b^T
//   pi_r,k: t (Rb^T w_k + pi_b (w_k . (c_b - c_wr)))^T / s,  w_k = R_rw^T e_k.
// refine_test checks them against automatic and numeric differentiation.
void PlaneTransferCost::HomographyAndJacobian(double const* const* parameters, Eigen::Matrix3d* H,
                                              HomographyJacobian* dH) const {
  const Eigen::Map<const Eigen::Quaterniond> qa(parameters[0]), qb(parameters[2]);
  const Eigen::Map<const Eigen::Vector3d> ca(parameters[1]), cb(parameters[3]), pi_r(parameters[4]);
  const Eigen::Matrix3d Ra = qa.toRotationMatrix(), Rb = qb.toRotationMatrix();
  const Eigen::Vector3d u = data_.R_rw.transpose() * pi_r;
  const Eigen::Vector3d f = cb - data_.c_wr;
  const double s = 1.0 - u.dot(f);
  const Eigen::Vector3d d = cb - ca;
  const Eigen::Vector3d t = Ra.transpose() * d;
  const Eigen::Vector3d pi_b = Rb.transpose() * u / s;
  *H = Ra.transpose() * Rb + t * pi_b.transpose();
  // Column p of dH (row-major 3 r + c) from a 3 x 3 derivative.
  auto put = [dH](int p, const Eigen::Matrix3d& D) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) (*dH)(3 * r + c, p) = D(r, c);
    }
  };
  Eigen::Matrix3d dR[4];
  RotationJacobian(parameters[0], dR);
  const Eigen::Matrix3d M_b = Rb + d * pi_b.transpose();
  for (int i = 0; i < 4; ++i) put(i, dR[i].transpose() * M_b);
  for (int k = 0; k < 3; ++k) put(4 + k, -Ra.row(k).transpose() * pi_b.transpose());
  RotationJacobian(parameters[2], dR);
  const Eigen::Matrix3d N = Ra.transpose() + t * u.transpose() / s;
  for (int i = 0; i < 4; ++i) put(7 + i, N * dR[i]);
  for (int k = 0; k < 3; ++k) {
    put(11 + k, (Ra.row(k).transpose() + t * (u[k] / s)) * pi_b.transpose());
  }
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d w_k = data_.R_rw.row(k).transpose();
    put(14 + k, t * ((Rb.transpose() * w_k + pi_b * w_k.dot(f)) / s).transpose());
  }
}

bool PlaneTransferCost::Evaluate(double const* const* parameters, double* residuals,
                                 double** jacobians) const {
  Eigen::Matrix3d H;
  HomographyJacobian dH;
  if (jacobians == nullptr) {
    H = data_.Homography(parameters[0], parameters[1], parameters[2], parameters[3], parameters[4]);
  } else {
    HomographyAndJacobian(parameters, &H, &dH);
  }
  for (size_t j = 0; j < data_.mbs.size(); ++j) {
    const PlaneTransferData::Mb& mb = data_.mbs[j];
    if (!data_.Residual(H, mb, residuals + 2 * j)) return false;
    if (jacobians == nullptr) continue;
    const Eigen::Vector3d X = H * mb.ray;
    const double inv_z = 1.0 / X.z();
    // dX/dp, row r: sum_k y_k dH(r, k)/dp.
    Eigen::Matrix<double, 3, kNumParameters, Eigen::RowMajor> dX;
    for (int r = 0; r < 3; ++r) {
      dX.row(r) = mb.ray.x() * dH.row(3 * r) + mb.ray.y() * dH.row(3 * r + 1) +
                  mb.ray.z() * dH.row(3 * r + 2);
    }
    const Eigen::Matrix<double, 1, kNumParameters> d_rx =
        (mb.scale * data_.fx * inv_z) * (dX.row(0) - (X.x() * inv_z) * dX.row(2));
    const Eigen::Matrix<double, 1, kNumParameters> d_ry =
        (mb.scale * data_.fy * inv_z) * (dX.row(1) - (X.y() * inv_z) * dX.row(2));
    for (int b = 0, offset = 0; b < 5; offset += kBlockSizes[b], ++b) {
      if (jacobians[b] == nullptr) continue;  // a constant block
      double* row_x = jacobians[b] + (2 * j) * kBlockSizes[b];
      double* row_y = row_x + kBlockSizes[b];
      for (int i = 0; i < kBlockSizes[b]; ++i) {
        row_x[i] = d_rx(offset + i);
        row_y[i] = d_ry(offset + i);
      }
    }
  }
  return true;
}

bool PlaneTransferCost::EvaluateNormalEquations(double const* const* parameters,
                                                double* half_squared_norm,
                                                Eigen::VectorXd* gradient,
                                                Eigen::MatrixXd* normal) const {
  Eigen::Matrix3d H;
  HomographyJacobian dH;
  HomographyAndJacobian(parameters, &H, &dH);
  TransferNormalSums sums;  // r_j = s_j (projection - x_earlier): axis scales s_j f
  double sq = 0;
  for (const PlaneTransferData::Mb& mb : data_.mbs) {
    double r[2];
    if (!data_.Residual(H, mb, r)) return false;
    sums.Add(mb.ray, H * mb.ray, mb.scale * data_.fx, mb.scale * data_.fy,
             Eigen::Vector2d(r[0], r[1]), 1.0);
    sq += r[0] * r[0] + r[1] * r[1];
  }
  const Eigen::Matrix<double, 9, 9> N = sums.N();
  const Eigen::Matrix<double, 9, 1> G = sums.g();
  *half_squared_norm = 0.5 * sq;
  *gradient = dH.transpose() * G;
  *normal = dH.transpose() * (N * dH);
  return true;
}

}  // namespace slapse
