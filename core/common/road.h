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
//
// How steeply the camera sees the road: the steepest ray of the image to the
// road, as its angle below the road's horizon (SteepestRoadDepressionDeg).
// The road's distance (the camera height) is measured through the flow of
// the road's rows, which grows with the square of a row's angle below the
// horizon; a road seen only far ahead (a short vertical field of view, or a
// camera pitched up) places the height poorly.
#pragma once

#include <algorithm>
#include <cmath>

#include <Eigen/Core>

#include "core/common/angles.h"
#include "core/common/camera.h"

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

// The largest angle below the road's horizon, degrees, of a ray through the
// image (`intrinsics`' frame, pixel centres 0 .. width - 1 and 0 .. height -
// 1) to the plane pi = n / d of the camera frame (n towards the plane):
// max asin(n . ray / |ray|). The rays within an angle of n form a convex
// cone, so the steepest ray is n itself when n projects into the image (90)
// and else lies on the image's border, which is sampled at 33 points per
// side, corners included. Negative when no ray of the image meets the
// plane; NaN for a zero pi or an empty image.
inline double SteepestRoadDepressionDeg(const Eigen::Vector3d& pi, const Intrinsics& intrinsics) {
  const double n = pi.norm();
  if (!(n > 0) || intrinsics.width_px < 1 || intrinsics.height_px < 1) return std::nan("");
  const Eigen::Vector3d normal = pi / n;
  const double w = intrinsics.width_px - 1.0, h = intrinsics.height_px - 1.0;
  if (normal.z() > 0) {
    const Eigen::Vector2d foot = intrinsics.Project(normal);
    if (foot.x() >= 0 && foot.x() <= w && foot.y() >= 0 && foot.y() <= h) return 90.0;
  }
  constexpr int kSteps = 32;
  double best = -1.0;
  auto try_pixel = [&](double u, double v) {
    const Eigen::Vector3d ray = intrinsics.Unproject({u, v});
    best = std::max(best, normal.dot(ray) / ray.norm());
  };
  for (int k = 0; k <= kSteps; ++k) {
    const double s = static_cast<double>(k) / kSteps;
    try_pixel(s * w, 0.0);
    try_pixel(s * w, h);
    try_pixel(0.0, s * h);
    try_pixel(w, s * h);
  }
  return RadToDeg(std::asin(std::clamp(best, -1.0, 1.0)));
}

}  // namespace slapse
