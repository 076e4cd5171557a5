// The road test: the one home of "is this plane the road".
//
// A plane n . X = d in a camera frame, with d > 0, has its normal n pointing
// from the camera towards the plane (so does pi = n / d, pi . X = 1). It is
// road-like when that normal is within max_angle_deg of the down direction:
//   n . down >= cos(max_angle_deg)          (n unit, down unit).
// One-sided: a road-like plane lies below the camera; a ceiling or the
// underside of a canopy (n . down < 0) is not the road.
//
// The callers pick `down` and the threshold (each a named option):
//  - the EKF's road plane: down = the camera's +y axis,
//    EkfOptions::road_max_angle_deg (and road_reid_max_angle_deg between a
//    new plane and the kept road);
//  - the metric scale from the camera height: down = +y,
//    ScaleOptions::road_max_angle_deg;
//  - plane extraction's street-scene prior: down = the learnt vertical,
//    PlaneExtractionOptions::max_road_tilt_deg.
#pragma once

#include <cmath>

#include <Eigen/Core>

#include "core/common/angles.h"

namespace slapse {

// The camera's down axis (x right, y down, z forward).
inline Eigen::Vector3d CameraDown() { return Eigen::Vector3d::UnitY(); }

// n . down / |n| for a plane's normal or its pi = n / d (any non-zero length).
inline double DownComponent(const Eigen::Vector3d& normal_or_pi, const Eigen::Vector3d& down) {
  return normal_or_pi.dot(down) / normal_or_pi.norm();
}

// True when the plane with normal (or pi) `normal_or_pi` is road-like: its
// normal within max_angle_deg of `down` (unit). False for a zero vector.
inline bool IsRoadLike(const Eigen::Vector3d& normal_or_pi, const Eigen::Vector3d& down,
                       double max_angle_deg) {
  return normal_or_pi.norm() > 0 &&
         DownComponent(normal_or_pi, down) >= std::cos(DegToRad(max_angle_deg));
}

}  // namespace slapse
