#include "core/common/camera.h"

#include <cmath>

namespace slapse {

Intrinsics Intrinsics::FromHorizontalFov(int width_px, int height_px, double hfov_deg) {
  Intrinsics k;
  k.width_px = width_px;
  k.height_px = height_px;
  k.fx_px = k.fy_px = 0.5 * width_px / std::tan(0.5 * hfov_deg * M_PI / 180.0);
  k.cx_px = 0.5 * (width_px - 1);
  k.cy_px = 0.5 * (height_px - 1);
  return k;
}

}  // namespace slapse
