#include "core/pipeline/update_stream.h"

#include <algorithm>
#include <cstddef>

namespace slapse {

void UpdateStream::CollectFramePoses(const Pipeline& pipeline, std::vector<FramePose>* out) {
  // Pose numbers (Pipeline): poses[k] is pose base + k.
  const std::vector<FramePose>& poses = pipeline.poses();
  const size_t base = pipeline.poses_forgotten(), end = base + poses.size();
  // Forgotten before they were sent (ForgetFinal's contract broken): lost.
  while (poses_sent_ < base) {
    revisions_sent_.push_back(-1);
    ++poses_sent_;
  }
  // The poses that were revisable at the last update: again if revised since.
  for (size_t n = std::max(revisable_from_, base); n < poses_sent_ && n < end; ++n) {
    int& sent = revisions_sent_[n - revisable_from_];
    if (poses[n - base].revision == sent) continue;
    out->push_back(poses[n - base]);
    sent = poses[n - base].revision;
  }
  for (size_t n = poses_sent_; n < end; ++n) {
    out->push_back(poses[n - base]);
    revisions_sent_.push_back(poses[n - base].revision);
  }
  poses_sent_ = std::max(poses_sent_, end);
  // Final poses are never sent again: their revisions need not be kept.
  const size_t from = std::max(revisable_from_, pipeline.first_revisable_pose());
  const size_t drop = std::min(from - revisable_from_, revisions_sent_.size());
  revisions_sent_.erase(revisions_sent_.begin(),
                        revisions_sent_.begin() + static_cast<std::ptrdiff_t>(drop));
  revisable_from_ += drop;
}

StepUpdates UpdateStream::Next(const Pipeline& pipeline, const PipelineStep& step) {
  StepUpdates out;
  out.pose.anchor_index = step.later_index;
  out.pose.timestamp_s = step.timestamp_s;
  out.pose.world_from_cam = step.world_from_cam;
  out.pose.tracking = step.tracking;
  out.pose.metric = step.metric;
  out.pose.note = step.note;
  out.pose.scale_note = step.scale_note;
  out.pose.extended = step.extended;
  if (step.tracking && !step.frame_poses.empty())
    out.pose.quality = step.frame_poses.back().quality;

  // A newly fixed scale rescales everything seen so far: send it all again.
  const std::map<int, MapPlane>& map = pipeline.plane_map();
  out.metric = pipeline.metric();
  if (out.metric != metric_) {
    metric_ = out.metric;
    out.rescaled = true;
    out.plane_map = &map;
    // (Nothing is forgotten while the scale may change: Pipeline::ForgetFinal.)
    points_sent_ = 0;
    poses_sent_ = 0;
    revisions_sent_.clear();
    revisable_from_ = 0;
  }
  const std::vector<TimedPose>& trajectory = pipeline.trajectory();
  const size_t anchors_base = pipeline.anchors_forgotten();
  const size_t first_new = std::max(points_sent_, anchors_base) - anchors_base;
  out.new_points.assign(trajectory.begin() + static_cast<std::ptrdiff_t>(first_new),
                        trajectory.end());
  points_sent_ = anchors_base + trajectory.size();
  CollectFramePoses(pipeline, &out.frame_poses);

  std::set<int> now;
  for (const PlaneTrack& t : step.planes) now.insert(t.track_id);
  auto change = [&](int id, PlaneChange::Kind kind) {
    auto it = map.find(id);
    if (it == map.end()) return;
    out.planes.push_back({kind, id, step.later_index, &it->second});
  };
  for (int id : now) {
    change(id, live_planes_.count(id) ? PlaneChange::Kind::kUpdated : PlaneChange::Kind::kAdded);
  }
  for (int id : live_planes_) {
    if (!now.count(id)) change(id, PlaneChange::Kind::kRemoved);
  }
  live_planes_ = std::move(now);
  return out;
}

}  // namespace slapse
