// A camera pose at a frame: the one timed-pose type of trajectories, estimated
// or true (pose convention: core/common/rigid3.h).
#pragma once

#include <cstdint>

#include "core/common/rigid3.h"

namespace slapse {

struct TimedPose {
  int64_t index = -1;        // frame index in display order
  double timestamp_s = 0.0;  // presentation time of the frame
  Rigid3d world_from_cam;
};

}  // namespace slapse
