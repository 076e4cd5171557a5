// The result files of a run: TUM and KITTI trajectories and the plane map as
// JSON. `slapse run` writes them from its Pipeline and `slapse export` from a
// server's snapshot, through these functions, so equal results give equal bytes.
#pragma once

#include <functional>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/pipeline/pipeline.h"

namespace slapse {

// TUM: a header comment, then "timestamp_s tx ty tz qx qy qz qw" per pose.
void WriteTrajectoryTum(const std::vector<TimedPose>& trajectory, std::ostream& out);
// The same file in parts, for a writer that gets its poses in pages:
// the header once, then the rows of each page (the bytes are equal).
void WriteTrajectoryTumHeader(std::ostream& out);
void WriteTrajectoryTumRows(const std::vector<TimedPose>& trajectory, std::ostream& out);

// KITTI: the 3x4 matrix [R | t] of each pose, row-major, one pose per line.
void WriteTrajectoryKitti(const std::vector<TimedPose>& trajectory, std::ostream& out);

// The timed poses of an all-frames trajectory (Pipeline::poses()), for the
// TUM and KITTI writers.
std::vector<TimedPose> TimedPosesOf(const std::vector<FramePose>& poses);

// trajectory_quality.csv, one row per pose in the order of the TUM file
// written from the same poses (docs/TRAJECTORY.md "Per-frame poses"):
//   frame_index,timestamp_s,kind,position_sigma,inliers,rms_px,revision,gap_frames,note
// kind: ANCHOR | FRAME | INTERPOLATED | COASTING | MOTION_ONLY; position_sigma in the
// trajectory's unit ("nan": none, see PoseQuality); note quoted.
void WritePoseQualityCsv(const std::vector<FramePose>& poses, std::ostream& out);
// In parts, as WriteTrajectoryTumHeader / Rows.
void WritePoseQualityCsvHeader(std::ostream& out);
void WritePoseQualityCsvRows(const std::vector<FramePose>& poses, std::ostream& out);

struct ResultJsonOptions {
  // Each plane's "seen_at_frames" (MapPlane::seen_indices); a server's plane
  // map does not keep them.
  bool seen_at_frames = true;
  // When set, a "trajectory" array (before "planes") with one object per pose:
  // frame_index, timestamp_s, t = [tx, ty, tz], q = [qx, qy, qz, qw].
  const std::vector<TimedPose>* trajectory = nullptr;
};

// The plane map as JSON (run's planes.json): frame, unit, planes by track id.
void WriteResultJson(const std::map<int, MapPlane>& planes, bool metric,
                     const ResultJsonOptions& options, std::ostream& out);

// Writes `path` with `write`; UNAVAILABLE if it cannot be opened or written.
Status WriteResultFile(const std::string& path, const std::function<void(std::ostream&)>& write);

}  // namespace slapse
