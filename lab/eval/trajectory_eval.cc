#include "lab/eval/trajectory_eval.h"

#include <algorithm>
#include <cmath>

#include <Eigen/SVD>

#include "core/common/angles.h"
#include "core/common/so3.h"

namespace slapse {

StatusOr<Sim3d> AlignSim3(const std::vector<Eigen::Vector3d>& from,
                          const std::vector<Eigen::Vector3d>& to) {
  const size_t n = from.size();
  if (n < 3 || to.size() != n) return InvalidArgumentError("Sim(3) alignment needs >= 3 pairs");
  Eigen::Vector3d mu_a = Eigen::Vector3d::Zero(), mu_b = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    mu_a += from[i];
    mu_b += to[i];
  }
  mu_a /= n;
  mu_b /= n;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double var_a = 0;
  for (size_t i = 0; i < n; ++i) {
    cov += (to[i] - mu_b) * (from[i] - mu_a).transpose();
    var_a += (from[i] - mu_a).squaredNorm();
  }
  cov /= n;
  var_a /= n;
  if (var_a < 1e-12) return InvalidArgumentError("Sim(3) alignment: points coincide");
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d S = Eigen::Matrix3d::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) S(2, 2) = -1;
  Sim3d sim;
  sim.R = svd.matrixU() * S * svd.matrixV().transpose();
  sim.scale = (svd.singularValues().asDiagonal() * S).trace() / var_a;
  sim.t = mu_b - sim.scale * sim.R * mu_a;
  return sim;
}

StatusOr<TrajectoryErrors> EvaluateTrajectory(const std::vector<TimedPose>& estimate,
                                              const std::vector<TimedPose>& truth) {
  std::map<int64_t, const TimedPose*> by_index;
  for (const TimedPose& p : truth) by_index[p.index] = &p;
  std::vector<const TimedPose*> est, gt;
  for (const TimedPose& p : estimate) {
    auto it = by_index.find(p.index);
    if (it == by_index.end()) continue;
    est.push_back(&p);
    gt.push_back(it->second);
  }
  if (est.size() < 3) return InvalidArgumentError("fewer than 3 poses match the ground truth");
  TrajectoryErrors e;
  e.poses = static_cast<int>(est.size());
  for (size_t k = 1; k < gt.size(); ++k) {
    e.distance_m +=
        (gt[k]->world_from_cam.translation - gt[k - 1]->world_from_cam.translation).norm();
  }
  // Paper's eps_D: both trajectories in their first camera C_0; the estimate
  // scaled so that its first step has the true length.
  const Rigid3d est0_inv = est[0]->world_from_cam.Inverse();
  const Rigid3d gt0_inv = gt[0]->world_from_cam.Inverse();
  auto est_in_c0 = [&](size_t k) { return (est0_inv * est[k]->world_from_cam).translation; };
  auto gt_in_c0 = [&](size_t k) { return (gt0_inv * gt[k]->world_from_cam).translation; };
  const double est_first = est_in_c0(1).norm(), gt_first = gt_in_c0(1).norm();
  e.first_step_scale = est_first > 1e-12 ? gt_first / est_first : 1.0;
  double sum_rel = 0;
  for (size_t k = 1; k < est.size(); ++k) {
    const Eigen::Vector3d truth_k = gt_in_c0(k);
    sum_rel += (e.first_step_scale * est_in_c0(k) - truth_k).norm() / truth_k.norm();
  }
  e.eps_D = sum_rel / (est.size() - 1);
  // ATE after Sim(3) alignment of the positions.
  std::vector<Eigen::Vector3d> a, b;
  for (size_t k = 0; k < est.size(); ++k) {
    a.push_back(est[k]->world_from_cam.translation);
    b.push_back(gt[k]->world_from_cam.translation);
  }
  auto sim = AlignSim3(a, b);
  if (!sim.ok()) return sim.status();
  e.sim3_scale = sim->scale;
  e.truth_from_estimate = *sim;
  double sq = 0;
  for (size_t k = 0; k < a.size(); ++k) sq += ((*sim) * a[k] - b[k]).squaredNorm();
  e.ate_rmse_m = std::sqrt(sq / a.size());
  // RPE between consecutive evaluated poses.
  double sq_t = 0, sq_r = 0;
  for (size_t k = 1; k < est.size(); ++k) {
    const Rigid3d de = est[k - 1]->world_from_cam.Inverse() * est[k]->world_from_cam;
    const Rigid3d dg = gt[k - 1]->world_from_cam.Inverse() * gt[k]->world_from_cam;
    sq_t += (sim->scale * de.translation - dg.translation).squaredNorm();
    const double ang = RadToDeg(LogSO3(de.R().transpose() * dg.R()).norm());
    sq_r += ang * ang;
  }
  e.rpe_trans_rmse_m = std::sqrt(sq_t / (est.size() - 1));
  e.rpe_rot_rmse_deg = std::sqrt(sq_r / (est.size() - 1));
  return e;
}

std::vector<TimedPose> TruthPoses(const GroundTruth& gt) {
  std::vector<TimedPose> truth;
  truth.reserve(gt.frames.size());
  for (size_t i = 0; i < gt.frames.size(); ++i) {
    truth.push_back(
        {static_cast<int64_t>(i), gt.frames[i].timestamp_s, gt.frames[i].world_from_cam});
  }
  return truth;
}

double MaxStepRatioJump(const std::vector<TimedPose>& estimate, const std::vector<TimedPose>& truth,
                        double metres_per_unit) {
  double worst = 0, last_ratio = 0;
  for (size_t k = 1; k < estimate.size(); ++k) {
    const int64_t a = estimate[k - 1].index, b = estimate[k].index;
    if (a < 0 || b >= static_cast<int64_t>(truth.size())) continue;
    const double true_m =
        (truth[b].world_from_cam.translation - truth[a].world_from_cam.translation).norm();
    const double est =
        (estimate[k].world_from_cam.translation - estimate[k - 1].world_from_cam.translation)
            .norm();
    if (!(true_m > 1e-3)) continue;
    const double ratio = metres_per_unit * est / true_m;
    if (last_ratio > 0) worst = std::max(worst, std::abs(ratio / last_ratio - 1.0));
    last_ratio = ratio;
  }
  return worst;
}

double TrueCameraHeightM(const GroundTruth& gt, int64_t index) {
  if (index < 0 || index >= static_cast<int64_t>(gt.frames.size())) return 0.0;
  for (const GtPlane& p : gt.planes) {
    if (p.kind != PlaneKind::kRoad) continue;
    return std::abs(p.distance_m - p.normal_world.dot(gt.frames[index].world_from_cam.translation));
  }
  return 0.0;
}

}  // namespace slapse
