// The macroblock grid: the one home of the 16-pixel cell that MVs, labels and
// merging are indexed by.
//
// Cell (col, row) covers pixels 16*col .. 16*col + 15 and 16*row .. 16*row + 15,
// i.e. image coordinates [16*col - 0.5, 16*col + 15.5) in the pixel-centre
// convention of core/common/camera.h. Its centre is (16*col + 7.5, 16*row + 7.5).
// Frames whose size is not a multiple of 16 get a partial last column/row.
#pragma once

#include <cmath>

#include <Eigen/Core>

namespace slapse {

// Side of a macroblock, pixels (all codecs slapse reads use 16x16 MBs).
constexpr int kMbSizePx = 16;

// Number of MB columns (rows) covering `size_px` pixels, partial cells included.
constexpr int MbCount(int size_px) { return (size_px + kMbSizePx - 1) / kMbSizePx; }

// Column (row) of the cell holding image coordinate `x_px` (may be outside the frame).
inline int MbCellOf(double x_px) {
  return static_cast<int>(std::floor((x_px + 0.5) / static_cast<double>(kMbSizePx)));
}

// Image coordinate of the centre of column (row) `cell`.
constexpr double MbCentrePx(int cell) { return kMbSizePx * cell + 0.5 * kMbSizePx - 0.5; }

struct MbCell {
  int col = 0, row = 0;
};
inline MbCell MbCellOfPixel(const Eigen::Vector2d& x_px) {
  return {MbCellOf(x_px.x()), MbCellOf(x_px.y())};
}
inline Eigen::Vector2d MbCentreOfCell(int col, int row) {
  return {MbCentrePx(col), MbCentrePx(row)};
}

}  // namespace slapse
