// Pictures of motion vectors for people: arrows over the decoded frame, like
// Fig. 1(a) of the SLAPSE paper.
#pragma once

#include <opencv2/core.hpp>

#include "core/mv/frame_record.h"

namespace slapse {

struct MvOverlayOptions {
  // Arrow length per pixel of motion; > 1 makes sub-pixel motion visible.
  double arrow_scale = 2.0;
  int thickness_px = 1;
  // Drawn in the picture's top-left corner: frame index, type, vector count.
  bool caption = true;
};

// Draws every vector of `frame` as an arrow from its block centre towards
// where the block's content sits in the reference frame (centre + scale *
// motion): red for past references, blue for future ones. The background is
// the frame's luma if the record carries it, else mid grey.
cv::Mat DrawMotionVectors(const FrameRecord& frame, int width_px, int height_px,
                          const MvOverlayOptions& options = {});

}  // namespace slapse
