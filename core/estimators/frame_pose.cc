#include "core/estimators/frame_pose.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "core/common/so3.h"

namespace slapse {
namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

// FramePoseResidual with R^T of the pose given (computed once per pass).
bool ResidualAt(const Intrinsics& k, const Eigen::Matrix3d& Rt, const Eigen::Vector3d& t,
                const FramePoseObservation& obs, Eigen::Vector2d* residual,
                Eigen::Matrix<double, 2, 6>* jacobian) {
  const Eigen::Vector3d X = Rt * (obs.point_world - t);  // X_c
  if (!(X.z() > 1e-9)) return false;
  const double iz = 1.0 / X.z();
  *residual =
      Eigen::Vector2d(k.fx_px * X.x() * iz + k.cx_px, k.fy_px * X.y() * iz + k.cy_px) - obs.x_px;
  if (jacobian != nullptr) {
    // dpi = d(projection)/dX_c = [a 0 b; 0 c d]; dX_c/dtheta = [X_c]_x and
    // dX_c/dt = -R^T, multiplied out (dpi [X_c]_x has rows a [X]_x.row(0) +
    // b [X]_x.row(2) and c [X]_x.row(1) + d [X]_x.row(2)).
    const double a = k.fx_px * iz, b = -a * X.x() * iz;
    const double c = k.fy_px * iz, d = -c * X.y() * iz;
    auto& J = *jacobian;
    J(0, 0) = -b * X.y();
    J(0, 1) = b * X.x() - a * X.z();
    J(0, 2) = a * X.y();
    J(1, 0) = c * X.z() - d * X.y();
    J(1, 1) = d * X.x();
    J(1, 2) = -c * X.x();
    J.block<1, 3>(0, 3) = -(a * Rt.row(0) + b * Rt.row(2));
    J.block<1, 3>(1, 3) = -(c * Rt.row(1) + d * Rt.row(2));
  }
  return true;
}

// The normal equations of the data term at `pose` (see frame_pose.h), the
// Huber weights from the current residuals.
struct NormalEquations {
  Matrix6d H = Matrix6d::Zero();
  Vector6d g = Vector6d::Zero();
  double median_depth = 1.0;
  int used = 0;
};

NormalEquations DataTerm(const Intrinsics& k, const std::vector<FramePoseObservation>& obs,
                         const Rigid3d& pose, const FramePoseOptions& o, bool median_depth) {
  NormalEquations ne;
  std::vector<double> depths;
  if (median_depth) depths.reserve(obs.size());
  const double extra2 = o.extra_sigma_px * o.extra_sigma_px;
  const Eigen::Matrix3d Rt = pose.R().transpose();
  // The rows sqrt(w / s2) J and sqrt(w / s2) r of the weighted observations.
  Eigen::Matrix<double, Eigen::Dynamic, 6, Eigen::RowMajor> A(2 * obs.size(), 6);
  Eigen::VectorXd b(2 * obs.size());
  Eigen::Index rows = 0;
  for (const FramePoseObservation& ob : obs) {
    Eigen::Vector2d r;
    Eigen::Matrix<double, 2, 6> J;
    if (!ResidualAt(k, Rt, pose.translation, ob, &r, &J)) continue;
    const double s2 = ob.variance_px2 + extra2;
    const double e = r.norm() / std::sqrt(s2);  // normalised residual
    const double w = e <= o.huber_k ? 1.0 : o.huber_k / e;
    const double sqrt_w = std::sqrt(w / s2);
    A.middleRows<2>(rows) = sqrt_w * J;
    b.segment<2>(rows) = sqrt_w * r;
    rows += 2;
    if (median_depth) depths.push_back(Rt.row(2).dot(ob.point_world - pose.translation));
    ++ne.used;
  }
  // H = A^T A, g = A^T b over the weighted rows, in one symmetric rank update.
  ne.H.selfadjointView<Eigen::Lower>().rankUpdate(A.topRows(rows).transpose());
  ne.H.triangularView<Eigen::StrictlyUpper>() = ne.H.transpose();
  ne.g.noalias() = A.topRows(rows).transpose() * b.head(rows);
  if (!depths.empty()) {
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    ne.median_depth = depths[depths.size() / 2];
  }
  return ne;
}

// The prior's information and its error e_p = [Log(R_p^T R), t - t_p]
// (d e_p / d delta taken as the identity: the pose stays near the prior).
void AddPrior(const Rigid3d& pose, const Rigid3d& prior, double sigma_rot, double sigma_pos,
              NormalEquations* ne) {
  if (sigma_rot > 0) {
    const Eigen::Vector3d e = LogSO3(prior.R().transpose() * pose.R());
    ne->H.topLeftCorner<3, 3>().diagonal().array() += 1.0 / (sigma_rot * sigma_rot);
    ne->g.head<3>() += e / (sigma_rot * sigma_rot);
  }
  if (sigma_pos > 0) {
    const Eigen::Vector3d e = pose.translation - prior.translation;
    ne->H.bottomRightCorner<3, 3>().diagonal().array() += 1.0 / (sigma_pos * sigma_pos);
    ne->g.tail<3>() += e / (sigma_pos * sigma_pos);
  }
}

// Smallest over largest eigenvalue of the data information with translation
// in units of the median depth (a translation dt moves pixels like a rotation
// of dt / depth).
double InformationRatio(const NormalEquations& ne) {
  Vector6d s;
  s << 1, 1, 1, ne.median_depth, ne.median_depth, ne.median_depth;
  const Matrix6d scaled = s.asDiagonal() * ne.H * s.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Matrix6d> es(scaled, Eigen::EigenvaluesOnly);
  const double max_ev = es.eigenvalues()(5);
  return max_ev > 0 ? es.eigenvalues()(0) / max_ev : 0.0;
}

}  // namespace

Status FramePoseOptions::Check(const std::string& who) const {
  if (max_iterations < 1 || !(extra_sigma_px >= 0) || !(huber_k > 0) || !(inlier_sigmas > 0) ||
      min_inliers < 6 || !std::isfinite(prior_rotation_rad) || !std::isfinite(prior_position_rel) ||
      !(min_information_ratio >= 0 && min_information_ratio < 1) || !(step_tolerance > 0)) {
    return InvalidArgumentError(who +
                                ": max_iterations must be >= 1, extra_sigma_px >= 0, huber_k, "
                                "inlier_sigmas and step_tolerance > 0, min_inliers >= 6, prior "
                                "sigmas finite and min_information_ratio in [0, 1)");
  }
  return Status::Ok();
}

bool FramePoseResidual(const Intrinsics& k, const Rigid3d& world_from_cam,
                       const FramePoseObservation& obs, Eigen::Vector2d* residual,
                       Eigen::Matrix<double, 2, 6>* jacobian) {
  return ResidualAt(k, world_from_cam.R().transpose(), world_from_cam.translation, obs, residual,
                    jacobian);
}

Rigid3d RetractFramePose(const Rigid3d& world_from_cam, const Eigen::Matrix<double, 6, 1>& delta) {
  Eigen::Quaterniond q(world_from_cam.R() * ExpSO3(delta.head<3>()));
  q.normalize();
  return Rigid3d(q, world_from_cam.translation + delta.tail<3>());
}

std::optional<Rigid3d> EstimateFramePose(const Intrinsics& intrinsics,
                                         const std::vector<FramePoseObservation>& observations,
                                         const Rigid3d& prior_world_from_cam, double step_length,
                                         const FramePoseOptions& o, FramePoseReport* report) {
  FramePoseReport local;
  FramePoseReport& rep = report != nullptr ? *report : local;
  rep = FramePoseReport();
  rep.observations = static_cast<int>(observations.size());
  if (rep.observations < o.min_inliers) {
    rep.no_model_reason =
        "too few vectors on known planes (" + std::to_string(rep.observations) + ")";
    return std::nullopt;
  }
  const double sigma_pos = o.prior_position_rel > 0 ? o.prior_position_rel * step_length : 0.0;
  Rigid3d pose = prior_world_from_cam;
  NormalEquations ne;
  for (rep.iterations = 0; rep.iterations < o.max_iterations; ++rep.iterations) {
    ne = DataTerm(intrinsics, observations, pose, o, false);
    if (ne.used < o.min_inliers) break;
    AddPrior(pose, prior_world_from_cam, o.prior_rotation_rad, sigma_pos, &ne);
    const Eigen::LDLT<Matrix6d> ldlt(ne.H);
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) break;
    const Vector6d delta = -ldlt.solve(ne.g);
    if (!delta.allFinite()) break;
    pose = RetractFramePose(pose, delta);
    if (delta.norm() < o.step_tolerance) break;
  }
  // The solution's data term, alone (degeneracy) and with the prior (covariance).
  ne = DataTerm(intrinsics, observations, pose, o, true);
  const double extra2 = o.extra_sigma_px * o.extra_sigma_px;
  double sq = 0;
  const Eigen::Matrix3d Rt = pose.R().transpose();
  for (const FramePoseObservation& ob : observations) {
    Eigen::Vector2d r;
    if (!ResidualAt(intrinsics, Rt, pose.translation, ob, &r, nullptr)) continue;
    if (r.squaredNorm() > o.inlier_sigmas * o.inlier_sigmas * (ob.variance_px2 + extra2)) continue;
    ++rep.inliers;
    sq += r.squaredNorm();
  }
  rep.rms_px = rep.inliers > 0 ? std::sqrt(sq / rep.inliers) : 0.0;
  if (rep.inliers < o.min_inliers) {
    rep.no_model_reason = "too few inliers (" + std::to_string(rep.inliers) + " of " +
                          std::to_string(rep.observations) + ")";
    return std::nullopt;
  }
  const double ratio = InformationRatio(ne);
  if (!(ratio > 0) || ratio < o.min_information_ratio) {
    rep.no_model_reason = "the vectors do not constrain all six pose directions";
    return std::nullopt;
  }
  AddPrior(pose, prior_world_from_cam, o.prior_rotation_rad, sigma_pos, &ne);
  rep.covariance = ne.H.inverse();
  rep.position_sigma = std::sqrt(std::max(0.0, rep.covariance.bottomRightCorner<3, 3>().trace()));
  return pose;
}

}  // namespace slapse
