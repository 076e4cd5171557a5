// Extracted planes for people: each plane's macroblocks as dots of one colour
// over the later anchor's picture, like Fig. 5 of the SLAPSE paper.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "core/planes/plane_extraction.h"

namespace slapse {

// Draws each plane's macroblocks (ExtractedPlane::mb_indices, cells of the
// later anchor on the MB grid of core/common/mb_grid.h) as dots at the cell
// centres, one colour per track id, captioned with the anchor pair.
// `luma`: the later anchor's luma plane (may be empty: grey background).
cv::Mat DrawPlanes(const std::vector<uint8_t>& luma, int width_px, int height_px,
                   int64_t earlier_index, int64_t later_index,
                   const std::vector<ExtractedPlane>& planes);

// A distinct colour per track id (BGR).
cv::Scalar TrackColour(int track_id);

}  // namespace slapse
