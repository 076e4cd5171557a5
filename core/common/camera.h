// Pinhole intrinsics and the pixel convention.
//
// Pixel convention (used everywhere in slapse): the centre of pixel (col, row)
// is at image coordinate (col, row); pixel edges lie on half-integers. This is
// OpenCV's convention. FFmpeg's exported block centres (`dst_x = 16*mb_x + 8`)
// use integer pixel *edges*, so the MV reader subtracts 0.5 to convert.
//
// Camera frame: x right, y down, z forward along the optical axis.
#pragma once

#include <string>

#include <Eigen/Core>

#include "core/common/status.h"

namespace slapse {

struct Intrinsics {
  double fx_px = 0, fy_px = 0;  // focal lengths in pixels
  double cx_px = 0, cy_px = 0;  // principal point in the pixel convention above
  int width_px = 0, height_px = 0;

  Eigen::Matrix3d K() const {
    Eigen::Matrix3d k;
    k << fx_px, 0, cx_px, 0, fy_px, cy_px, 0, 0, 1;
    return k;
  }
  // Projects a point in the camera frame (z > 0) to pixel coordinates.
  Eigen::Vector2d Project(const Eigen::Vector3d& x_cam) const {
    return {fx_px * x_cam.x() / x_cam.z() + cx_px, fy_px * x_cam.y() / x_cam.z() + cy_px};
  }
  // Ray direction (z = 1) in the camera frame through pixel `uv`.
  Eigen::Vector3d Unproject(const Eigen::Vector2d& uv) const {
    return {(uv.x() - cx_px) / fx_px, (uv.y() - cy_px) / fy_px, 1.0};
  }
  // A centred camera with the given horizontal field of view.
  static Intrinsics FromHorizontalFov(int width_px, int height_px, double hfov_deg);
};

// The one check of intrinsics a user or a client gave: focal lengths finite
// and > 0, principal point finite, width/height >= 0 (0 = take the stream's).
// `what` names the source in the message (e.g. "intrinsics file 'k.json'").
Status ValidateIntrinsics(const Intrinsics& k, const std::string& what = "intrinsics");

}  // namespace slapse
