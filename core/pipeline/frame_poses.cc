#include "core/pipeline/frame_poses.h"

#include <cmath>
#include <limits>
#include <utility>

#include "core/common/mb_grid.h"

namespace slapse {
namespace {

// A pair spans at most a GOP segment or an IPPP chain; more buffered frames
// than this means no pair is closing (e.g. intra-only input): the oldest go.
constexpr size_t kMaxBufferedFrames = 128;

}  // namespace

Rigid3d InterpolatePose(const TimedPose& a, const TimedPose& b, double timestamp_s) {
  const double span = b.timestamp_s - a.timestamp_s;
  const double alpha = span > 0 ? (timestamp_s - a.timestamp_s) / span : 0.0;
  return Rigid3d(a.world_from_cam.rotation.slerp(alpha, b.world_from_cam.rotation),
                 (1 - alpha) * a.world_from_cam.translation + alpha * b.world_from_cam.translation);
}

const char* PoseKindName(PoseKind kind) {
  switch (kind) {
    case PoseKind::kAnchor:
      return "ANCHOR";
    case PoseKind::kFrame:
      return "FRAME";
    case PoseKind::kInterpolated:
      return "INTERPOLATED";
    case PoseKind::kCoasting:
      return "COASTING";
    case PoseKind::kMotionOnly:
      return "MOTION_ONLY";
  }
  return "?";
}

std::string ScaleSupport::Summary() const {
  if (anchor_steps == 0) return "no anchor step tracked";
  std::string out = "planes measured " +
                    std::to_string(static_cast<int>(std::lround(100 * PlaneStepShare()))) +
                    " % of the " + std::to_string(anchor_steps) + " anchor steps";
  if (road_frame_steps > 0) {
    out += " (" + std::to_string(road_frame_steps) +
           " of them the road in the B frames next to the earlier anchor)";
  }
  if (Weak()) {
    out +=
        ": the remaining steps take their length from the motion model (constant speed), so "
        "expect the scale to drift with the speed by several % (docs/TRAJECTORY.md \"Scale "
        "support\")";
  }
  return out;
}

FramePoser::FramePoser(const Intrinsics& intrinsics, double sigma_px, FramePoserOptions options)
    : intrinsics_(intrinsics),
      sigma_px_(sigma_px),
      options_(std::move(options)),
      mb_cols_(MbCount(intrinsics.width_px)),
      mb_rows_(MbCount(intrinsics.height_px)) {}

void FramePoser::Buffer(const FrameRecord& frame) {
  if (!options_.enabled && !options_.keep_frames) return;
  FrameRecord kept;  // everything but the luma
  kept.index = frame.index;
  kept.timestamp_s = frame.timestamp_s;
  kept.type = frame.type;
  kept.prev_anchor_index = frame.prev_anchor_index;
  kept.next_anchor_index = frame.next_anchor_index;
  kept.corrupt = frame.corrupt;
  kept.coded_index = frame.coded_index;
  kept.mvs = frame.mvs;
  frames_.push_back(std::move(kept));
  if (frames_.size() > kMaxBufferedFrames) frames_.pop_front();
}

void FramePoser::Skip(int64_t later_index) {
  while (!frames_.empty() && frames_.front().index <= later_index) frames_.pop_front();
}

void FramePoser::Reset() {
  frames_.clear();
  last_anchor_index_ = -1;
  last_anchor_labels_.clear();
}

FramePoser::Labels FramePoser::AnchorLabels(const PosedAnchorPair& posed, bool later) const {
  Labels labels(static_cast<size_t>(mb_cols_) * mb_rows_, -1);
  std::map<int, bool> held;
  for (const PlaneTrack& t : *posed.planes) held[t.track_id] = true;
  const std::vector<Correspondence>& corr = posed.pair->correspondences;
  for (size_t k = 0; k < posed.extracted->size(); ++k) {
    const int id = (*posed.extracted_filter_ids)[k];
    if (!held.count(id)) continue;
    for (int i : (*posed.extracted)[k].correspondence_indices) {
      const MbCell c = MbCellOfPixel(later ? corr[i].x_later_px : corr[i].x_earlier_px);
      if (c.col < 0 || c.row < 0 || c.col >= mb_cols_ || c.row >= mb_rows_) continue;
      labels[static_cast<size_t>(c.row) * mb_cols_ + c.col] = id;
    }
  }
  // The earlier anchor was the previous pair's later one: its labels fill the gaps.
  if (!later && last_anchor_index_ == posed.earlier.index &&
      last_anchor_labels_.size() == labels.size()) {
    for (size_t i = 0; i < labels.size(); ++i) {
      if (labels[i] < 0 && held.count(last_anchor_labels_[i])) labels[i] = last_anchor_labels_[i];
    }
  }
  return labels;
}

std::vector<FramePoseObservation> FramePoser::Observe(const FrameRecord& frame,
                                                      const std::map<int64_t, Reference>& refs,
                                                      const std::map<int, Plane3d>& planes_world,
                                                      Labels* own_labels) const {
  std::vector<FramePoseObservation> out;
  own_labels->assign(static_cast<size_t>(mb_cols_) * mb_rows_, -1);
  auto cell_index = [&](const Eigen::Vector2d& x) -> int {
    const MbCell c = MbCellOfPixel(x);
    if (c.col < 0 || c.row < 0 || c.col >= mb_cols_ || c.row >= mb_rows_) return -1;
    return c.row * mb_cols_ + c.col;
  };
  for (const MotionVector& mv : frame.mvs) {
    const bool past = mv.direction == RefDirection::kPast;
    if (!past && frame.type != PictureType::kB) continue;
    auto ref = refs.find(past ? frame.prev_anchor_index : frame.next_anchor_index);
    if (ref == refs.end()) continue;
    const Eigen::Vector2d x(mv.x_px, mv.y_px);
    const Eigen::Vector2d p = x + Eigen::Vector2d(mv.dx_px, mv.dy_px);  // in the reference
    const int ci = cell_index(p);
    if (ci < 0 || ref->second.labels[ci] < 0) continue;
    const int id = ref->second.labels[ci];
    auto plane = planes_world.find(id);
    if (plane == planes_world.end()) continue;
    // The ray of p from the reference camera meets the plane: n . (c + s dir) = d.
    const Rigid3d& T = ref->second.world_from_cam;
    const Eigen::Vector3d dir = T.rotation * intrinsics_.Unproject(p);
    const double denom = plane->second.normal.dot(dir);
    if (std::abs(denom) < 1e-9) continue;
    const double s = (plane->second.distance - plane->second.normal.dot(T.translation)) / denom;
    if (!(s > 0) || !std::isfinite(s)) continue;
    FramePoseObservation ob;
    ob.point_world = T.translation + s * dir;
    ob.x_px = x;
    ob.variance_px2 = sigma_px_ * sigma_px_;
    out.push_back(ob);
    const int own = cell_index(x);
    if (own >= 0) (*own_labels)[own] = id;
  }
  return out;
}

std::vector<FramePose> FramePoser::PoseBetween(const PosedAnchorPair& posed) {
  std::vector<FramePose> out;
  if (!options_.enabled) {  // frames kept for their vectors only (keep_frames)
    Skip(posed.later.index);
    return out;
  }
  const TimedPose& a = posed.earlier;
  const TimedPose& b = posed.later;
  std::map<int, Plane3d> planes_world;
  for (const PlaneTrack& t : *posed.planes) {
    if (!(t.pi.norm() > 0)) continue;
    planes_world[t.track_id] = TransformPlane(b.world_from_cam, Plane3d::FromInverseDepth(t.pi));
  }
  std::map<int64_t, Reference> refs;
  refs[a.index] = {a.world_from_cam, AnchorLabels(posed, false)};
  refs[b.index] = {b.world_from_cam, AnchorLabels(posed, true)};
  const double step_length = (b.world_from_cam.translation - a.world_from_cam.translation).norm();
  for (const FrameRecord& f : frames_) {
    if (f.index <= a.index || f.index >= b.index) continue;
    const Rigid3d prior = InterpolatePose(a, b, f.timestamp_s);
    Labels own;
    const auto observations = Observe(f, refs, planes_world, &own);
    FramePoseReport rep;
    const auto pose =
        EstimateFramePose(intrinsics_, observations, prior, step_length, options_.estimator, &rep);
    FramePose fp;
    fp.pose = {f.index, f.timestamp_s, pose.has_value() ? *pose : prior};
    fp.quality.kind = pose.has_value() ? PoseKind::kFrame : PoseKind::kInterpolated;
    fp.quality.position_sigma =
        pose.has_value() ? rep.position_sigma : std::numeric_limits<double>::quiet_NaN();
    fp.quality.inliers = rep.inliers;
    fp.quality.rms_px = rep.rms_px;
    if (!pose.has_value()) fp.quality.note = "interpolated: " + rep.no_model_reason;
    // A P frame inside a chained pair is the next P frame's reference.
    if (f.type == PictureType::kP) refs[f.index] = {fp.pose.world_from_cam, std::move(own)};
    out.push_back(std::move(fp));
  }
  last_anchor_index_ = b.index;
  last_anchor_labels_ = refs[b.index].labels;
  Skip(b.index);
  return out;
}

}  // namespace slapse
