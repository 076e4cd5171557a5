#include "core/refine/plane_transfer_cost.h"

#include <utility>

namespace slapse {
namespace {

constexpr int kBlockSizes[5] = {4, 3, 4, 3, 3};  // q_a, c_a, q_b, c_b, pi_r
constexpr int kNumParameters = 17;
using Jet = ceres::Jet<double, kNumParameters>;

}  // namespace

PlaneTransferCost::PlaneTransferCost(PlaneTransferData data) : data_(std::move(data)) {
  set_num_residuals(2 * static_cast<int>(data_.mbs.size()));
  for (int size : kBlockSizes) mutable_parameter_block_sizes()->push_back(size);
}

bool PlaneTransferCost::Evaluate(double const* const* parameters, double* residuals,
                                 double** jacobians) const {
  // H and, when asked for, dH/dp (row 3 r + c of dH is H(r, c)'s gradient).
  Eigen::Matrix3d H;
  Eigen::Matrix<double, 9, kNumParameters, Eigen::RowMajor> dH;
  if (jacobians == nullptr) {
    H = data_.Homography(parameters[0], parameters[1], parameters[2], parameters[3], parameters[4]);
  } else {
    Jet p[kNumParameters];
    const Jet* blocks[5];
    for (int b = 0, offset = 0; b < 5; offset += kBlockSizes[b], ++b) {
      for (int i = 0; i < kBlockSizes[b]; ++i) p[offset + i] = Jet(parameters[b][i], offset + i);
      blocks[b] = p + offset;
    }
    const Eigen::Matrix<Jet, 3, 3> H_jet =
        data_.Homography(blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        H(r, c) = H_jet(r, c).a;
        dH.row(3 * r + c) = H_jet(r, c).v.transpose();
      }
    }
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

}  // namespace slapse
