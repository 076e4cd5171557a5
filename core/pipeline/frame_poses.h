// Poses for the frames between tracked anchors, and the quality of every pose
// (docs/METHOD.md "Per-frame poses").
//
// The filter gives a pose per anchor pair (the later anchor). The frames in
// between (B frames; the P frames inside a chained IPPP pair) have their own
// motion vectors into frames whose pose and planes are then known: a B
// frame's past vectors point into the earlier anchor and its future vectors
// into the later one; a P frame's vectors point into the frame before it.
// FramePoser buffers the frames of the open segment and, once the pair's
// anchors are posed, estimates each frame's pose from those vectors
// (core/estimators/frame_pose.h), seeded by and pulled towards the anchors'
// interpolation at the frame's timestamp. Which plane a vector lands on is
// read from plane labels per macroblock cell of its reference: in the two
// anchors from the pair's extracted planes (the later anchor's cells and the
// earlier anchor's matching points, plus the previous pair's labels of the
// earlier anchor), in an in-between P frame from the labels its own vectors
// point at. A frame without enough vectors on known planes keeps the
// interpolated pose, flagged INTERPOLATED with the reason: never silently.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <vector>

#include "core/common/camera.h"
#include "core/common/plane.h"
#include "core/common/timed_pose.h"
#include "core/ekf/plane_ekf.h"
#include "core/estimators/frame_pose.h"
#include "core/merge/correspondence.h"
#include "core/mv/frame_record.h"
#include "core/planes/plane_extraction.h"

namespace slapse {

// Where a pose comes from (the wire enum PoseKind has the same values).
enum class PoseKind {
  kAnchor = 1,        // an anchor updated by the filter with plane observations
  kFrame = 2,         // a frame between anchors, from its own motion vectors
  kInterpolated = 3,  // a frame between anchors without a model: the anchors' interpolation
  kCoasting = 4,      // an anchor the filter only predicted (no plane observed)
  // An anchor without a plane observed whose rotation and direction of travel
  // come from the pair's epipolar geometry; its step length is the filter's
  // motion model (PlaneEkf::UpdateMotion).
  kMotionOnly = 5,
};
// "ANCHOR", "FRAME", "INTERPOLATED", "COASTING", "MOTION_ONLY".
const char* PoseKindName(PoseKind kind);

// How much a pose can be trusted.
struct PoseQuality {
  PoseKind kind = PoseKind::kAnchor;
  // 1-sigma position uncertainty, trajectory length unit, relative to the
  // neighbouring anchors: for anchors the filter's step translation (relative
  // to the previous anchor), for FRAME poses the estimator's covariance given
  // the anchors; NaN for INTERPOLATED (no own measurement) and for the anchor
  // the trajectory (re)starts on.
  double position_sigma = 0.0;
  int inliers = 0;      // measurements the pose rests on (MBs for anchors, vectors for frames)
  double rms_px = 0.0;  // their residual RMS
  // Frames without a pose just before this one (a loss: the trajectory was
  // re-initialised and continues from the last pose); 0 normally.
  int64_t gap_frames = 0;
  std::string note;  // why INTERPOLATED / COASTING, or the restart
};

// How much of a trajectory's length the planes measured: a run can be told
// good from bad by it (docs/TRAJECTORY.md "Scale support"). An anchor step
// whose filter update observed a tracked plane (PoseKind::kAnchor), or whose
// length the road in the B frames measured (PipelineOptions::
// road_from_frames), has its length measured; another COASTING or
// MOTION_ONLY one takes it from the motion model (constant speed), so where
// those dominate the scale drifts with the speed. On the 48 tuning drives
// the runs with planes under kMinPlaneStepShare of their steps had a median
// ATE of 0.68 % of the distance and eps_D 6.5 % (H.264 IPPP; MPEG-2 IBBBP
// 0.87 and 4.9 %), the others 0.11 % and 0.9 % (0.12, 0.9 %); the reporting
// drives split the same way. A held share is no guarantee: the worst held
// runs reach 1.3-1.5 %.
struct ScaleSupport {
  static constexpr double kMinPlaneStepShare = 0.7;
  int64_t anchor_steps = 0;  // tracked anchor steps (one a tracked pair)
  int64_t plane_steps = 0;   // of which a plane measured the length (see above)
  // Of plane_steps, those only the road in the B frames measured (COASTING
  // or MOTION_ONLY anchors).
  int64_t road_frame_steps = 0;

  // Counts one anchor step posed as `kind`, whose length the road in the B
  // frames measured when `road_in_frames`.
  void Count(PoseKind kind, bool road_in_frames = false) {
    ++anchor_steps;
    plane_steps += kind == PoseKind::kAnchor || road_in_frames;
    road_frame_steps += kind != PoseKind::kAnchor && road_in_frames;
  }
  // plane_steps / anchor_steps (0 without steps).
  double PlaneStepShare() const {
    return anchor_steps > 0 ? static_cast<double>(plane_steps) / anchor_steps : 0.0;
  }
  // Planes measured fewer than kMinPlaneStepShare of the steps (false without steps).
  bool Weak() const { return anchor_steps > 0 && PlaneStepShare() < kMinPlaneStepShare; }
  // One line for a person: the share, and what a weak share means.
  std::string Summary() const;
};

// The pose between two timed poses at `timestamp_s`: slerp of the rotation,
// linear in position (the prior of the frames between anchors).
Rigid3d InterpolatePose(const TimedPose& a, const TimedPose& b, double timestamp_s);

// A pose of the all-frames trajectory.
struct FramePose {
  TimedPose pose;
  PoseQuality quality;
  // 0 when first reported; increased each time the pipeline changes this
  // pose afterwards (e.g. a refinement of its anchors). Consumers replace a
  // pose by a later revision of the same frame index.
  int revision = 0;
};

struct FramePoserOptions {
  bool enabled = true;  // false: frames between anchors get no pose at all
  // Buffer the frames (buffered()) even when not `enabled`: the pipeline
  // sets it for PipelineOptions::road_from_frames. Not on the wire.
  bool keep_frames = false;
  FramePoseOptions estimator;
  Status Check(const std::string& who = "FramePoserOptions") const {
    return estimator.Check(who + ".estimator");
  }
};

// One tracked anchor pair with everything the frames between need.
struct PosedAnchorPair {
  const AnchorPair* pair = nullptr;
  TimedPose earlier, later;                                // the anchors' poses
  const std::vector<ExtractedPlane>* extracted = nullptr;  // the pair's planes
  const std::vector<int>* extracted_filter_ids = nullptr;  // their filter ids
  const std::vector<PlaneTrack>* planes = nullptr;         // filter planes, in the later camera
};

class FramePoser {
 public:
  // sigma_px: the stream's MV error (StreamInfo::mv_sigma_px()).
  FramePoser(const Intrinsics& intrinsics, double sigma_px, FramePoserOptions options = {});

  // Keeps `frame`'s vectors until its pair closes (not its luma).
  void Buffer(const FrameRecord& frame);
  // The poses of the buffered frames strictly between the pair's anchors, in
  // display order; drops the buffered frames up to the later anchor.
  std::vector<FramePose> PoseBetween(const PosedAnchorPair& posed);
  // The frames buffered since the last pair closed, in display order.
  const std::deque<FrameRecord>& buffered() const { return frames_; }
  // The pair closed without a tracked pose: drops the frames up to it.
  void Skip(int64_t later_index);
  void Reset();

 private:
  using Labels = std::vector<int>;  // filter track id per MB cell, -1: none
  struct Reference {
    Rigid3d world_from_cam;
    Labels labels;
  };
  Labels AnchorLabels(const PosedAnchorPair& posed, bool later) const;
  // The frame's vectors on known planes (from `refs`), and its own labels.
  std::vector<FramePoseObservation> Observe(const FrameRecord& frame,
                                            const std::map<int64_t, Reference>& refs,
                                            const std::map<int, Plane3d>& planes_world,
                                            Labels* own_labels) const;

  Intrinsics intrinsics_;
  double sigma_px_;
  FramePoserOptions options_;
  int mb_cols_, mb_rows_;
  std::deque<FrameRecord> frames_;
  int64_t last_anchor_index_ = -1;  // the later anchor of the last posed pair
  Labels last_anchor_labels_;       // its labels
};

}  // namespace slapse
