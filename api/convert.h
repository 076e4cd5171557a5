// Conversions between the service's wire messages (proto/slapse/v1) and the
// core structs, both ways, in one place for the server, the client and the
// CLI.
//
// Options: a core struct field the proto does not carry keeps the struct's
// default; a proto "0 = default" field (eps_h_px) becomes the core struct's
// default (PlaneExtractionOptions{}), never a retyped number. Of the scale
// fields only the one the scale source uses travels; the others keep the
// ScaleOptions defaults. Poses: Rigid3d <-> Pose (translation, unit
// quaternion x, y, z, w), frames as in core/common/rigid3.h.
#pragma once

#include <map>
#include <vector>

#include "core/common/camera.h"
#include "core/common/rigid3.h"
#include "core/common/timed_pose.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::api {

// Camera (width_px / height_px 0: the stream's).
v1::Intrinsics IntrinsicsToProto(const Intrinsics& k);
Intrinsics IntrinsicsFromProto(const v1::Intrinsics& k);

// Pose.
v1::Pose PoseToProto(const Rigid3d& world_from_cam);
Rigid3d PoseFromProto(const v1::Pose& pose);
v1::Vec3 Vec3ToProto(const Eigen::Vector3d& v);
Eigen::Vector3d Vec3FromProto(const v1::Vec3& v);

// Pipeline options: eps_h_px, the scale source with its one parameter, and
// whether the frames between anchors are posed (anchors_only).
v1::PipelineOptions PipelineOptionsToProto(const PipelineOptions& options);
PipelineOptions PipelineOptionsFromProto(const v1::PipelineOptions& options);
v1::PipelineOptions::ScaleSource ScaleSourceToProto(ScaleOptions::Source source);
ScaleOptions::Source ScaleSourceFromProto(v1::PipelineOptions::ScaleSource source);

// Stream options: whether to re-encode codecs without vectors (unset: the
// MvReaderOptions default). Only `reencode` travels; the rest keeps
// MvReaderOptions{}'s values.
v1::StreamOptions StreamOptionsToProto(const MvReaderOptions& options);
MvReaderOptions StreamOptionsFromProto(const v1::StreamOptions& options);
// What a reader knows about its stream, as Session.stream_report.
v1::StreamReport StreamReportToProto(const StreamInfo& info, const ReadStats& stats);

// Trajectory: one point, and a GetTrajectory snapshot as
// Pipeline::trajectory() holds it.
v1::Trajectory::Point TimedPoseToProto(const TimedPose& point);
TimedPose TimedPoseFromProto(const v1::Trajectory::Point& point);
std::vector<TimedPose> TrajectoryFromProto(const v1::Trajectory& trajectory);

// Per-frame poses and their quality (core/pipeline/frame_poses.h). A
// Trajectory point carries a FramePose's index, time, pose, quality and
// revision; FramePosesFromProto gives a GetTrajectory snapshot as
// Pipeline::poses() holds it.
v1::PoseQuality PoseQualityToProto(const PoseQuality& quality);
PoseQuality PoseQualityFromProto(const v1::PoseQuality& quality);
v1::FramePose FramePoseToProto(const FramePose& pose);
FramePose FramePoseFromProto(const v1::FramePose& pose);
v1::Trajectory::Point FramePoseToPoint(const FramePose& pose);
FramePose FramePoseFromPoint(const v1::Trajectory::Point& point);
std::vector<FramePose> FramePosesFromProto(const v1::Trajectory& trajectory);

// Plane map: one plane, and a GetPlaneMap snapshot by track id. The wire
// carries neither seen_indices, pi_cam, mb_indices nor support_world (nor the
// first / last seen indices): those stay empty / -1.
v1::PlaneMap::Plane MapPlaneToProto(const MapPlane& plane);
MapPlane MapPlaneFromProto(const v1::PlaneMap::Plane& plane);
std::map<int, MapPlane> PlaneMapFromProto(const v1::PlaneMap& plane_map);

}  // namespace slapse::api
