// Per-frame poses (Pipeline::poses()) against the simulator's truth: position
// errors by pose kind after the anchors' own Sim(3) alignment, so frames and
// anchors are measured in one frame, and the same frames interpolated between
// their anchors as the baseline an estimate must beat.
#pragma once

#include <vector>

#include "core/common/status.h"
#include "core/common/timed_pose.h"
#include "core/pipeline/frame_poses.h"
#include "lab/eval/trajectory_eval.h"

namespace slapse {

struct PositionErrorStats {
  int poses = 0;
  double rmse_m = 0.0, max_m = 0.0;
  // Local stats only: RMSE of the error of the rotation from the frame's
  // earlier anchor to the frame (estimated against true), deg.
  double rot_rmse_deg = 0.0;
};

struct FramePoseErrors {
  TrajectoryErrors anchors;         // EvaluateTrajectory on ANCHOR/COASTING/MOTION_ONLY poses
  PositionErrorStats anchor;        // their position errors after that alignment
  PositionErrorStats frame;         // FRAME poses (own estimate)
  PositionErrorStats interpolated;  // INTERPOLATED poses
  // The FRAME poses' frames, interpolated between their anchors instead.
  PositionErrorStats frame_baseline;
  // Local errors, relative to the frame's two anchors: a FRAME pose's error
  // minus its anchors' errors interpolated to its timestamp (what the frame's
  // own estimate adds or removes, free of the anchors' drift), and the same
  // for the interpolated pose (the true path's deviation from a straight
  // line between the true anchors).
  PositionErrorStats frame_local, frame_baseline_local;
  PositionErrorStats all;  // every pose with a truth
};

// `poses` and `truth` matched by frame index. Needs >= 3 anchors with a truth.
StatusOr<FramePoseErrors> EvaluateFramePoses(const std::vector<FramePose>& poses,
                                             const std::vector<TimedPose>& truth);

}  // namespace slapse
