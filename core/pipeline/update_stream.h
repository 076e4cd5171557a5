// UpdateStream: what a live consumer of a Pipeline is told after each step.
//
// The Pipeline answers "where is the camera, which planes does the filter
// hold" after every anchor pair; a watcher wants changes instead: one pose
// update per pair, plane events (ADDED the first step the filter holds a
// track, UPDATED while it keeps holding it, REMOVED the first step it no
// longer does), and the snapshots kept current (the trajectory points and
// map planes that are new since the last step, or, the step the metric scale
// got fixed and everything seen so far was rescaled, all of them anew).
// The server converts these structs to its wire messages and transports them
// (server/session_runner.cc); nothing here knows the wire format.
//
// Per-frame poses: every frame's pose (Pipeline::poses()) goes out once when
// added; a pose the pipeline changes later (its revision counter goes up;
// only poses at or after Pipeline::first_revisable_pose() can change) goes
// out again with the new revision. Applying the updates in order gives
// exactly Pipeline::poses(), preceded by what Pipeline::ForgetFinal dropped
// (ForgetFinal only drops what was sent and can no longer change).
//
// Thread-safety: none; one UpdateStream per Pipeline, fed in step order.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "core/common/rigid3.h"
#include "core/common/timed_pose.h"
#include "core/pipeline/pipeline.h"

namespace slapse {

// The camera at the later anchor of a pair (PipelineStep's fields).
struct PoseChange {
  int64_t anchor_index = -1;  // display index of the later anchor
  double timestamp_s = 0.0;   // of the later anchor
  Rigid3d world_from_cam;
  bool tracking = false;   // the filter is running (pose and planes valid)
  bool metric = false;     // lengths are metres
  std::string note;        // why the step did not track, if it did not
  std::string scale_note;  // PipelineStep::scale_note: how the metric scale stands
  bool extended = false;   // PipelineStep::extended: its poses come with a later step
  PoseQuality quality;     // the anchor's, when tracking
};

// A filter plane that appeared, changed or went.
struct PlaneChange {
  enum class Kind { kAdded, kUpdated, kRemoved };
  Kind kind = Kind::kUpdated;
  int track_id = -1;
  int64_t anchor_index = -1;  // the step's later anchor
  // The plane as the pipeline's map holds it after the step. Points into
  // Pipeline::plane_map(): valid until the pipeline's next Push or Break.
  const MapPlane* plane = nullptr;
};

struct StepUpdates {
  PoseChange pose;
  // Ascending track id: ADDED / UPDATED for the planes the filter holds after
  // the step, then REMOVED for those it held before and no longer does. A
  // track the map does not hold (never recorded) gets no event.
  std::vector<PlaneChange> planes;

  // Snapshots. `rescaled`: the metric scale was fixed at this step and the
  // pipeline rescaled everything seen so far; a snapshot drops what it holds
  // and takes `plane_map` whole (then applies `planes` as usual) and
  // `new_points` (then the whole trajectory).
  bool rescaled = false;
  bool metric = false;                                 // lengths are metres
  const std::map<int, MapPlane>* plane_map = nullptr;  // set when rescaled; as `plane`
  // Trajectory points added since the last update (anchors; a revised
  // anchor is not sent again here: see frame_poses).
  std::vector<TimedPose> new_points;

  // The all-frames trajectory (Pipeline::poses()): the poses added or
  // revised since the last update, in display order. A consumer appends a
  // pose whose frame index it does not hold and replaces the one it holds
  // by a pose of the same index (whose `revision` is then higher); on
  // `rescaled` it drops them all first (they all come again).
  std::vector<FramePose> frame_poses;
};

class UpdateStream {
 public:
  // The updates after `pipeline` returned `step` (call once per step, in order).
  StepUpdates Next(const Pipeline& pipeline, const PipelineStep& step);

 private:
  // The poses of Pipeline::poses() added or revised since the last call.
  void CollectFramePoses(const Pipeline& pipeline, std::vector<FramePose>* out);

  std::set<int> live_planes_;  // track ids the filter held after the previous step
  size_t points_sent_ = 0;     // trajectory points (anchors) already in an update
  // Pipeline::poses(), by pose number: how many were sent, where those that
  // may have been revised since the last update begin, and the revision sent
  // of each from there on (revisions_sent_[k]: pose revisable_from_ + k).
  size_t poses_sent_ = 0;
  size_t revisable_from_ = 0;
  std::deque<int> revisions_sent_;
  bool metric_ = false;  // the scale of what was sent
};

}  // namespace slapse
