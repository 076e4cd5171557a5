#include "core/pipeline/update_stream.h"

#include <cstddef>

namespace slapse {

void UpdateStream::CollectFramePoses(const Pipeline& pipeline, std::vector<FramePose>* out) {
  const std::vector<FramePose>& poses = pipeline.poses();
  const size_t sent = pose_revisions_sent_.size();
  for (size_t i = revisable_from_; i < sent && i < poses.size(); ++i) {
    if (poses[i].revision == pose_revisions_sent_[i]) continue;
    out->push_back(poses[i]);
    pose_revisions_sent_[i] = poses[i].revision;
  }
  for (size_t i = sent; i < poses.size(); ++i) {
    out->push_back(poses[i]);
    pose_revisions_sent_.push_back(poses[i].revision);
  }
  revisable_from_ = pipeline.first_revisable_pose();
}

StepUpdates UpdateStream::Next(const Pipeline& pipeline, const PipelineStep& step) {
  StepUpdates out;
  out.pose.anchor_index = step.later_index;
  out.pose.timestamp_s = step.timestamp_s;
  out.pose.world_from_cam = step.world_from_cam;
  out.pose.tracking = step.tracking;
  out.pose.metric = step.metric;
  out.pose.note = step.note;
  if (step.tracking && !step.frame_poses.empty())
    out.pose.quality = step.frame_poses.back().quality;

  // A newly fixed scale rescales everything seen so far: send it all again.
  const std::map<int, MapPlane>& map = pipeline.plane_map();
  out.metric = pipeline.metric();
  if (out.metric != metric_) {
    metric_ = out.metric;
    out.rescaled = true;
    out.plane_map = &map;
    points_sent_ = 0;
    pose_revisions_sent_.clear();
    revisable_from_ = 0;
  }
  const std::vector<TimedPose>& trajectory = pipeline.trajectory();
  out.new_points.assign(trajectory.begin() + static_cast<std::ptrdiff_t>(points_sent_),
                        trajectory.end());
  points_sent_ = trajectory.size();
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
