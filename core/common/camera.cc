#include "core/common/camera.h"

#include <cmath>

#include "core/common/angles.h"

namespace slapse {

Intrinsics Intrinsics::FromHorizontalFov(int width_px, int height_px, double hfov_deg) {
  Intrinsics k;
  k.width_px = width_px;
  k.height_px = height_px;
  k.fx_px = k.fy_px = 0.5 * width_px / std::tan(DegToRad(0.5 * hfov_deg));
  k.cx_px = 0.5 * (width_px - 1);
  k.cy_px = 0.5 * (height_px - 1);
  return k;
}

Status ValidateIntrinsics(const Intrinsics& k, const std::string& what) {
  if (!(std::isfinite(k.fx_px) && std::isfinite(k.fy_px) && k.fx_px > 0 && k.fy_px > 0)) {
    return InvalidArgumentError(what + ": fx_px and fy_px must be finite and > 0, got " +
                                std::to_string(k.fx_px) + ", " + std::to_string(k.fy_px));
  }
  if (!(std::isfinite(k.cx_px) && std::isfinite(k.cy_px))) {
    return InvalidArgumentError(what + ": cx_px and cy_px must be finite");
  }
  if (k.width_px < 0 || k.height_px < 0) {
    return InvalidArgumentError(what + ": width_px and height_px must be >= 0 (0 = the stream's)");
  }
  return Status::Ok();
}

}  // namespace slapse
