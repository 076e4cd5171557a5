#include "api/convert.h"

namespace slapse::api {

v1::Intrinsics IntrinsicsToProto(const Intrinsics& k) {
  v1::Intrinsics out;
  out.set_fx_px(k.fx_px);
  out.set_fy_px(k.fy_px);
  out.set_cx_px(k.cx_px);
  out.set_cy_px(k.cy_px);
  out.set_width_px(k.width_px);
  out.set_height_px(k.height_px);
  return out;
}

Intrinsics IntrinsicsFromProto(const v1::Intrinsics& k) {
  Intrinsics out;
  out.fx_px = k.fx_px();
  out.fy_px = k.fy_px();
  out.cx_px = k.cx_px();
  out.cy_px = k.cy_px();
  out.width_px = k.width_px();
  out.height_px = k.height_px();
  return out;
}

v1::Pose PoseToProto(const Rigid3d& t) {
  v1::Pose out;
  out.set_tx(t.translation.x());
  out.set_ty(t.translation.y());
  out.set_tz(t.translation.z());
  out.set_qx(t.rotation.x());
  out.set_qy(t.rotation.y());
  out.set_qz(t.rotation.z());
  out.set_qw(t.rotation.w());
  return out;
}

Rigid3d PoseFromProto(const v1::Pose& q) {
  return Rigid3d(Eigen::Quaterniond(q.qw(), q.qx(), q.qy(), q.qz()),
                 Eigen::Vector3d(q.tx(), q.ty(), q.tz()));
}

v1::Vec3 Vec3ToProto(const Eigen::Vector3d& v) {
  v1::Vec3 out;
  out.set_x(v.x());
  out.set_y(v.y());
  out.set_z(v.z());
  return out;
}

Eigen::Vector3d Vec3FromProto(const v1::Vec3& v) { return Eigen::Vector3d(v.x(), v.y(), v.z()); }

v1::PipelineOptions::ScaleSource ScaleSourceToProto(ScaleOptions::Source source) {
  switch (source) {
    case ScaleOptions::Source::kFirstStep:
      return v1::PipelineOptions::FIRST_STEP;
    case ScaleOptions::Source::kSpeed:
      return v1::PipelineOptions::SPEED;
    case ScaleOptions::Source::kCameraHeight:
      return v1::PipelineOptions::CAMERA_HEIGHT;
    case ScaleOptions::Source::kUpToScale:
      break;
  }
  return v1::PipelineOptions::UP_TO_SCALE;
}

ScaleOptions::Source ScaleSourceFromProto(v1::PipelineOptions::ScaleSource source) {
  switch (source) {
    case v1::PipelineOptions::FIRST_STEP:
      return ScaleOptions::Source::kFirstStep;
    case v1::PipelineOptions::SPEED:
      return ScaleOptions::Source::kSpeed;
    case v1::PipelineOptions::CAMERA_HEIGHT:
      return ScaleOptions::Source::kCameraHeight;
    default:
      return ScaleOptions::Source::kUpToScale;
  }
}

v1::PipelineOptions PipelineOptionsToProto(const PipelineOptions& o) {
  v1::PipelineOptions out;
  out.set_eps_h_px(o.extraction.eps_h_px);
  out.set_scale_source(ScaleSourceToProto(o.scale.source));
  out.set_anchors_only(!o.frame_poses.enabled);
  out.set_window_refine(o.window_refine);
  out.set_motion_only_steps(o.motion_only_steps);
  out.set_road_from_frames(o.road_from_frames);
  out.set_init_max_baseline_s(o.init_max_baseline_s);
  out.set_track_max_baseline_s(o.track_max_baseline_s);
  out.set_refine_window_anchors(o.refine.window_anchors);
  out.set_road_attitude_sigma_deg(o.refine.road_attitude_sigma_deg);
  out.set_min_pair_span_s(o.merge.min_pair_span_s);
  switch (o.scale.source) {
    case ScaleOptions::Source::kFirstStep:
      out.set_first_step_m(o.scale.first_step_m);
      break;
    case ScaleOptions::Source::kSpeed:
      out.set_speed_mps(o.scale.speed_mps);
      break;
    case ScaleOptions::Source::kCameraHeight:
      out.set_camera_height_m(o.scale.camera_height_m);
      break;
    case ScaleOptions::Source::kUpToScale:
      break;
  }
  return out;
}

PipelineOptions PipelineOptionsFromProto(const v1::PipelineOptions& p) {
  PipelineOptions o;
  // 0 = the default: PlaneExtractionOptions' own.
  if (p.eps_h_px() > 0) o.extraction.eps_h_px = p.eps_h_px();
  o.frame_poses.enabled = !p.anchors_only();
  o.scale.source = ScaleSourceFromProto(p.scale_source());
  // Unset / 0 = the core struct's defaults.
  if (p.has_window_refine()) o.window_refine = p.window_refine();
  if (p.has_motion_only_steps()) o.motion_only_steps = p.motion_only_steps();
  if (p.has_road_from_frames()) o.road_from_frames = p.road_from_frames();
  if (p.has_init_max_baseline_s()) o.init_max_baseline_s = p.init_max_baseline_s();
  if (p.has_track_max_baseline_s()) o.track_max_baseline_s = p.track_max_baseline_s();
  if (p.refine_window_anchors() > 0) o.refine.window_anchors = p.refine_window_anchors();
  if (p.has_min_pair_span_s()) o.merge.min_pair_span_s = p.min_pair_span_s();
  if (p.has_road_attitude_sigma_deg()) {
    o.refine.road_attitude_sigma_deg = p.road_attitude_sigma_deg();
  }
  switch (o.scale.source) {
    case ScaleOptions::Source::kFirstStep:
      o.scale.first_step_m = p.first_step_m();
      break;
    case ScaleOptions::Source::kSpeed:
      o.scale.speed_mps = p.speed_mps();
      break;
    case ScaleOptions::Source::kCameraHeight:
      o.scale.camera_height_m = p.camera_height_m();
      break;
    case ScaleOptions::Source::kUpToScale:
      break;
  }
  return o;
}

v1::StreamOptions StreamOptionsToProto(const MvReaderOptions& options) {
  v1::StreamOptions p;
  p.set_reencode(options.reencode);
  return p;
}

MvReaderOptions StreamOptionsFromProto(const v1::StreamOptions& p) {
  MvReaderOptions o;
  if (p.has_reencode()) o.reencode = p.reencode();
  return o;
}

v1::StreamReport StreamReportToProto(const StreamInfo& info, const ReadStats& stats) {
  v1::StreamReport p;
  const bool reencoded = !info.reencoded_from.empty();
  p.set_codec(reencoded ? info.reencoded_from : info.codec_name);
  p.set_reencoded(reencoded);
  if (reencoded) p.set_reencoded_to(info.codec_name);
  p.set_decode_cpu_s(stats.decode_cpu_s);
  p.set_reencode_cpu_s(stats.reencode_cpu_s);
  p.set_frames(stats.frames);
  for (const std::string& note : stats.notes) p.add_notes(note);
  return p;
}

v1::Trajectory::Point TimedPoseToProto(const TimedPose& point) {
  v1::Trajectory::Point out;
  out.set_anchor_index(point.index);
  out.set_timestamp_s(point.timestamp_s);
  *out.mutable_world_from_cam() = PoseToProto(point.world_from_cam);
  return out;
}

TimedPose TimedPoseFromProto(const v1::Trajectory::Point& point) {
  TimedPose out;
  out.index = point.anchor_index();
  out.timestamp_s = point.timestamp_s();
  out.world_from_cam = PoseFromProto(point.world_from_cam());
  return out;
}

std::vector<TimedPose> TrajectoryFromProto(const v1::Trajectory& trajectory) {
  std::vector<TimedPose> out;
  out.reserve(trajectory.points_size());
  for (const v1::Trajectory::Point& p : trajectory.points()) out.push_back(TimedPoseFromProto(p));
  return out;
}

v1::PoseQuality PoseQualityToProto(const PoseQuality& q) {
  v1::PoseQuality out;
  // PoseKind and PoseQuality.Kind share their values.
  out.set_kind(static_cast<v1::PoseQuality::Kind>(static_cast<int>(q.kind)));
  out.set_position_sigma(q.position_sigma);
  out.set_inliers(q.inliers);
  out.set_rms_px(q.rms_px);
  out.set_gap_frames(q.gap_frames);
  out.set_note(q.note);
  return out;
}

PoseQuality PoseQualityFromProto(const v1::PoseQuality& q) {
  PoseQuality out;
  switch (q.kind()) {
    case v1::PoseQuality::FRAME:
      out.kind = PoseKind::kFrame;
      break;
    case v1::PoseQuality::INTERPOLATED:
      out.kind = PoseKind::kInterpolated;
      break;
    case v1::PoseQuality::COASTING:
      out.kind = PoseKind::kCoasting;
      break;
    case v1::PoseQuality::MOTION_ONLY:
      out.kind = PoseKind::kMotionOnly;
      break;
    default:  // ANCHOR, and a point of a server without per-frame poses
      out.kind = PoseKind::kAnchor;
      break;
  }
  out.position_sigma = q.position_sigma();
  out.inliers = q.inliers();
  out.rms_px = q.rms_px();
  out.gap_frames = q.gap_frames();
  out.note = q.note();
  return out;
}

v1::FramePose FramePoseToProto(const FramePose& p) {
  v1::FramePose out;
  out.set_frame_index(p.pose.index);
  out.set_timestamp_s(p.pose.timestamp_s);
  *out.mutable_world_from_cam() = PoseToProto(p.pose.world_from_cam);
  *out.mutable_quality() = PoseQualityToProto(p.quality);
  out.set_revision(p.revision);
  return out;
}

FramePose FramePoseFromProto(const v1::FramePose& p) {
  FramePose out;
  out.pose.index = p.frame_index();
  out.pose.timestamp_s = p.timestamp_s();
  out.pose.world_from_cam = PoseFromProto(p.world_from_cam());
  out.quality = PoseQualityFromProto(p.quality());
  out.revision = p.revision();
  return out;
}

v1::Trajectory::Point FramePoseToPoint(const FramePose& p) {
  v1::Trajectory::Point out = TimedPoseToProto(p.pose);
  *out.mutable_quality() = PoseQualityToProto(p.quality);
  out.set_revision(p.revision);
  return out;
}

FramePose FramePoseFromPoint(const v1::Trajectory::Point& point) {
  FramePose out;
  out.pose = TimedPoseFromProto(point);
  out.quality = PoseQualityFromProto(point.quality());
  out.revision = point.revision();
  return out;
}

std::vector<FramePose> FramePosesFromProto(const v1::Trajectory& trajectory) {
  std::vector<FramePose> out;
  out.reserve(trajectory.points_size());
  for (const v1::Trajectory::Point& p : trajectory.points()) out.push_back(FramePoseFromPoint(p));
  return out;
}

v1::PlaneMap::Plane MapPlaneToProto(const MapPlane& p) {
  v1::PlaneMap::Plane out;
  out.set_track_id(p.track_id);
  *out.mutable_normal_world() = Vec3ToProto(p.normal_world);
  out.set_distance(p.distance_m);
  out.set_first_seen_s(p.first_seen_s);
  out.set_last_seen_s(p.last_seen_s);
  out.set_observations(p.observations);
  return out;
}

MapPlane MapPlaneFromProto(const v1::PlaneMap::Plane& p) {
  MapPlane out;
  out.track_id = p.track_id();
  out.normal_world = Vec3FromProto(p.normal_world());
  out.distance_m = p.distance();
  out.first_seen_s = p.first_seen_s();
  out.last_seen_s = p.last_seen_s();
  out.observations = p.observations();
  return out;
}

std::map<int, MapPlane> PlaneMapFromProto(const v1::PlaneMap& plane_map) {
  std::map<int, MapPlane> out;
  for (const v1::PlaneMap::Plane& p : plane_map.planes()) out[p.track_id()] = MapPlaneFromProto(p);
  return out;
}

}  // namespace slapse::api
