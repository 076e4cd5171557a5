// Accuracy of an estimated trajectory and plane map against ground truth
// (paper Sec. VII; how they are reported: docs/TRAJECTORY.md), plus the standard ATE/RPE.
#pragma once

#include <map>
#include <vector>

#include <Eigen/Core>

#include "core/common/rigid3.h"
#include "core/common/status.h"
#include "core/common/timed_pose.h"
#include "lab/gt/ground_truth.h"

namespace slapse {

// Similarity transform b_from_a: x_b = s R x_a + t.
struct Sim3d {
  double scale = 1.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const { return scale * R * x + t; }
};

// Least-squares similarity (Umeyama) mapping points `from` onto `to`.
// Needs >= 3 non-collinear points; otherwise INVALID_ARGUMENT.
StatusOr<Sim3d> AlignSim3(const std::vector<Eigen::Vector3d>& from,
                          const std::vector<Eigen::Vector3d>& to);

struct TrajectoryErrors {
  int poses = 0;
  double distance_m = 0.0;  // ground-truth path length over the evaluated poses
  double eps_D = 0.0;       // paper: mean ||t_0k - t^_0k|| / ||t^_0k||, in C_0, first-step scale
  double ate_rmse_m = 0.0;  // after Sim(3) alignment
  double rpe_trans_rmse_m = 0.0;  // per step, Sim(3)-aligned scale
  double rpe_rot_rmse_deg = 0.0;
  double sim3_scale = 1.0;        // metres per estimated unit (alignment)
  double first_step_scale = 1.0;  // metres per estimated unit (first step)
  Sim3d truth_from_estimate;      // the ATE alignment (world frames)
};

// `estimate` and `truth` are matched by index; poses missing in either are
// skipped. Needs >= 3 matched poses.
StatusOr<TrajectoryErrors> EvaluateTrajectory(const std::vector<TimedPose>& estimate,
                                              const std::vector<TimedPose>& truth);

// The true camera pose of every frame of a simulated drive.
std::vector<TimedPose> TruthPoses(const GroundTruth& gt);

// Scale steadiness (issue 12): per consecutive estimated poses k-1, k the
// ratio of the estimated step length (times `metres_per_unit`) to the true
// one; returns the largest |ratio_k / ratio_{k-1} - 1| (0 with < 3 poses).
// `truth` is indexed by frame (TruthPoses).
double MaxStepRatioJump(const std::vector<TimedPose>& estimate, const std::vector<TimedPose>& truth,
                        double metres_per_unit);

// The camera's true height above the drive's road plane in frame `index`
// (0 when the drive has no road plane).
double TrueCameraHeightM(const GroundTruth& gt, int64_t index);

}  // namespace slapse
