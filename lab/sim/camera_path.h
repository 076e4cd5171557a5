// The simulated car's camera path through a street scene.
//
// The car drives along the centre of the right lane (Scene::lane_offset_m) at
// a speed that varies smoothly within [min_speed_mps, max_speed_mps]. The
// camera sits camera_height_m above the road, looks along the lane's tangent
// (the heading averaged over +-heading_smoothing_m of arc length, so the yaw
// rate has no jumps where bends begin), pitched down by a fixed angle plus a
// small pitch/roll vibration, and bounces up and down by up to bounce_m
// (sums of sinusoids). Everything is a deterministic function of the seed.
//
// Poses are world_from_cam (core/common/rigid3.h), camera frame x right, y
// down, z forward; frame i is at t = i / fps.
#pragma once

#include <cstdint>
#include <vector>

#include "core/common/rigid3.h"
#include "core/common/status.h"
#include "lab/sim/scene.h"

namespace slapse {

struct PathOptions {
  uint64_t seed = 1;
  double fps = 30.0;
  int num_frames = 300;
  double min_speed_mps = 25.0 / 3.6;
  double max_speed_mps = 50.0 / 3.6;
  double start_s_m = 5.0;  // arc length of the first frame along the centreline
  double camera_height_min_m = 1.3, camera_height_max_m = 1.6;
  double pitch_down_min_deg = 2.0, pitch_down_max_deg = 5.0;
  double vibration_deg = 0.3;  // peak pitch vibration; roll gets 0.7 of it
  // Peak vertical vibration of the camera (the car's body on its suspension,
  // periods 0.4-1.5 s): the camera's height above the road is
  // camera_height_m +- bounce_m, never exactly constant.
  double bounce_m = 0.015;
  double heading_smoothing_m = 4.0;  // half-window of the heading average
  // Also pose the camera half a frame after each frame (an interlaced
  // camera's second field): CameraPath::half_frame_world_from_cam.
  bool half_frame_poses = false;
};

struct CameraPath {
  std::vector<double> timestamps_s;
  std::vector<Rigid3d> world_from_cam;
  // With PathOptions::half_frame_poses: the pose at timestamps_s[i] + 0.5 / fps.
  std::vector<Rigid3d> half_frame_world_from_cam;
  std::vector<double> s_m;        // centreline arc length of each frame
  std::vector<double> speed_mps;  // the car's speed at each frame
  double distance_m = 0.0;        // driven from the first to the last frame
  double camera_height_m = 0.0;   // mean height above the road (the bounce is about it)
  double pitch_down_deg = 0.0;    // fixed part of the pitch
};

// Longest distance a path with these options can cover, for sizing a street.
double MaxPathLength(const PathOptions& options);

StatusOr<CameraPath> GenerateCameraPath(const Scene& scene, const PathOptions& options);

// Camera orientation for a heading (rad, CCW from world +x), pitch (rad,
// positive looks down) and roll (rad, about the optical axis).
Eigen::Matrix3d WorldFromCamRotation(double heading_rad, double pitch_down_rad, double roll_rad);

}  // namespace slapse
