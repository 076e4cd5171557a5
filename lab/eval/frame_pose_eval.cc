#include "lab/eval/frame_pose_eval.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <map>

#include <Eigen/Geometry>

namespace slapse {
namespace {

bool IsAnchorKind(PoseKind k) {
  return k == PoseKind::kAnchor || k == PoseKind::kCoasting || k == PoseKind::kMotionOnly;
}

void Add(double e, PositionErrorStats* s, double rot_deg = 0.0) {
  ++s->poses;
  s->rmse_m += e * e;  // sums of squares until Finish
  s->rot_rmse_deg += rot_deg * rot_deg;
  s->max_m = std::max(s->max_m, e);
}

void Finish(PositionErrorStats* s) {
  s->rmse_m = s->poses > 0 ? std::sqrt(s->rmse_m / s->poses) : 0.0;
  s->rot_rmse_deg = s->poses > 0 ? std::sqrt(s->rot_rmse_deg / s->poses) : 0.0;
}

}  // namespace

StatusOr<FramePoseErrors> EvaluateFramePoses(const std::vector<FramePose>& poses,
                                             const std::vector<TimedPose>& truth) {
  std::vector<TimedPose> anchors;
  for (const FramePose& p : poses) {
    if (IsAnchorKind(p.quality.kind)) anchors.push_back(p.pose);
  }
  auto trajectory = EvaluateTrajectory(anchors, truth);
  if (!trajectory.ok()) return trajectory.status();
  FramePoseErrors out;
  out.anchors = *trajectory;
  const Sim3d& align = out.anchors.truth_from_estimate;
  std::map<int64_t, const TimedPose*> truth_at;
  for (const TimedPose& t : truth) truth_at[t.index] = &t;
  auto residual = [&](const Rigid3d& est, int64_t index) -> Eigen::Vector3d {
    return align * est.translation - truth_at.at(index)->world_from_cam.translation;
  };
  auto error = [&](const Rigid3d& est, int64_t index) { return residual(est, index).norm(); };
  // The rotation from anchor `a` to frame `f`, estimated against true (no
  // alignment needed; a position alignment leaves the roll about a straight
  // path undetermined).
  auto rel_rot_error_deg = [&](const Rigid3d& est_a, int64_t a, const Rigid3d& est_f, int64_t f) {
    const Eigen::Matrix3d est = est_a.R().transpose() * est_f.R();
    const Eigen::Matrix3d tru =
        truth_at.at(a)->world_from_cam.R().transpose() * truth_at.at(f)->world_from_cam.R();
    return Eigen::AngleAxisd(tru.transpose() * est).angle() * 180.0 / M_PI;
  };
  const TimedPose* before = nullptr;  // the last anchor
  for (size_t i = 0; i < poses.size(); ++i) {
    const FramePose& p = poses[i];
    if (IsAnchorKind(p.quality.kind)) before = &p.pose;
    if (!truth_at.count(p.pose.index)) continue;
    const double e = error(p.pose.world_from_cam, p.pose.index);
    Add(e, &out.all);
    if (IsAnchorKind(p.quality.kind)) {
      Add(e, &out.anchor);
      continue;
    }
    Add(e, p.quality.kind == PoseKind::kFrame ? &out.frame : &out.interpolated);
    if (p.quality.kind != PoseKind::kFrame || before == nullptr) continue;
    const auto after =
        std::find_if(poses.begin() + static_cast<std::ptrdiff_t>(i), poses.end(),
                     [](const FramePose& q) { return IsAnchorKind(q.quality.kind); });
    if (after == poses.end() || !truth_at.count(before->index) ||
        !truth_at.count(after->pose.index)) {
      continue;
    }
    const Rigid3d interpolated = InterpolatePose(*before, after->pose, p.pose.timestamp_s);
    Add(error(interpolated, p.pose.index), &out.frame_baseline);
    // The anchors' errors, interpolated to the frame (alpha as InterpolatePose).
    const double span = after->pose.timestamp_s - before->timestamp_s;
    const double alpha = span > 0 ? (p.pose.timestamp_s - before->timestamp_s) / span : 0.0;
    const Eigen::Vector3d anchors = (1 - alpha) * residual(before->world_from_cam, before->index) +
                                    alpha * residual(after->pose.world_from_cam, after->pose.index);
    Add((residual(p.pose.world_from_cam, p.pose.index) - anchors).norm(), &out.frame_local,
        rel_rot_error_deg(before->world_from_cam, before->index, p.pose.world_from_cam,
                          p.pose.index));
    Add((residual(interpolated, p.pose.index) - anchors).norm(), &out.frame_baseline_local,
        rel_rot_error_deg(before->world_from_cam, before->index, interpolated, p.pose.index));
  }
  for (PositionErrorStats* s : {&out.anchor, &out.frame, &out.interpolated, &out.frame_baseline,
                                &out.all, &out.frame_local, &out.frame_baseline_local}) {
    Finish(s);
  }
  return out;
}

}  // namespace slapse
