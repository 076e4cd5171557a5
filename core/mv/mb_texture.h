// How well a macroblock's content pins down its motion: the smaller
// eigenvalue of the block's mean structure tensor (docs/METHOD.md "Texture
// gate").
//
// For a block of N pixels with intensity noise sigma_n (levels), the
// displacement a block matcher finds has, to first order (Lucas-Kanade),
// covariance sigma_n^2 (sum over the block of g g^T)^-1, g the intensity
// gradient. Its worst direction has variance sigma_n^2 / (N lambda_min), with
// lambda_min the smaller eigenvalue of the mean of g g^T over the block, in
// (levels / px)^2. A flat block (sky, a blank wall) has lambda_min ~ 0: the
// encoder's vector there is whatever its rate term prefers (the predicted
// vector), not the motion; a block with 1-D texture (a guard rail, a lane
// line) has lambda_min ~ 0 too (the aperture problem): its vector along the
// structure is free.
#pragma once

#include <cstdint>
#include <vector>

namespace slapse {

// lambda_min of every macroblock of a luma plane (width x height, `stride`
// bytes per row), row-major over MbCount(width) x MbCount(height) cells
// (core/common/mb_grid.h; partial cells use their pixels inside the frame).
// Gradients are central differences, (I(x+1) - I(x-1)) / 2, at every fourth
// pixel in each direction from (1, 1) of the cell (16 samples per full cell:
// the sky's ~0 and a textured block's >= 1 stay orders of magnitude apart, at
// a sixteenth of the reads), clamped at the frame border. (levels / px)^2.
std::vector<float> MbTextureMinEigen(const uint8_t* luma, int stride, int width, int height);

}  // namespace slapse
