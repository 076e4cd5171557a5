// A server's results as the core types an offline run holds, so a client can
// write them with the same writers (core/pipeline/result_io.h) and compare
// them with an offline Pipeline's; and the camera as the service's proto.
#pragma once

#include <map>
#include <vector>

#include "core/common/camera.h"
#include "core/pipeline/pipeline.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::client {

// The poses of a GetTrajectory snapshot, as Pipeline::trajectory() holds them.
std::vector<Pipeline::TrajectoryPoint> TrajectoryFromProto(const v1::Trajectory& trajectory);

// The planes of a GetPlaneMap snapshot by track id. A server keeps neither
// seen_indices, pi_cam, mb_indices nor support_world: those stay empty.
std::map<int, MapPlane> PlaneMapFromProto(const v1::PlaneMap& plane_map);

// Intrinsics for CreateSession (width_px / height_px 0: the stream's).
v1::Intrinsics IntrinsicsToProto(const Intrinsics& k);

}  // namespace slapse::client
