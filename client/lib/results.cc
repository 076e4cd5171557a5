#include "client/lib/results.h"

namespace slapse::client {

std::vector<Pipeline::TrajectoryPoint> TrajectoryFromProto(const v1::Trajectory& trajectory) {
  std::vector<Pipeline::TrajectoryPoint> out;
  out.reserve(trajectory.points_size());
  for (const v1::Trajectory::Point& p : trajectory.points()) {
    const v1::Pose& q = p.world_from_cam();
    out.push_back({p.anchor_index(), p.timestamp_s(),
                   Rigid3d(Eigen::Quaterniond(q.qw(), q.qx(), q.qy(), q.qz()),
                           Eigen::Vector3d(q.tx(), q.ty(), q.tz()))});
  }
  return out;
}

std::map<int, MapPlane> PlaneMapFromProto(const v1::PlaneMap& plane_map) {
  std::map<int, MapPlane> out;
  for (const v1::PlaneMap::Plane& p : plane_map.planes()) {
    MapPlane& mp = out[p.track_id()];
    mp.track_id = p.track_id();
    mp.normal_world =
        Eigen::Vector3d(p.normal_world().x(), p.normal_world().y(), p.normal_world().z());
    mp.distance_m = p.distance();
    mp.first_seen_s = p.first_seen_s();
    mp.last_seen_s = p.last_seen_s();
    mp.observations = p.observations();
  }
  return out;
}

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

}  // namespace slapse::client
