#include "core/mv/mb_texture.h"

#include <algorithm>
#include <cmath>

#include "core/common/mb_grid.h"

namespace slapse {
namespace {

// Accumulates a cell's sums of gx^2, gx gy, gy^2 (g the undivided central
// difference, 2 x levels / px) over its samples.
struct TensorSums {
  int32_t xx = 0, xy = 0, yy = 0, n = 0;  // <= 16 samples of <= 255^2
  void Add(int gx, int gy) {
    xx += gx * gx;
    xy += gx * gy;
    yy += gy * gy;
    ++n;
  }
  // lambda_min of the mean tensor S / (4 n), (levels / px)^2.
  float MinEigen() const {
    if (n == 0) return 0.0f;
    const double scale = 1.0 / (4.0 * static_cast<double>(n));
    const double a = xx * scale, b = xy * scale, d = yy * scale;
    const double disc = std::sqrt(0.25 * (a - d) * (a - d) + b * b);
    return static_cast<float>(std::max(0.0, 0.5 * (a + d) - disc));
  }
};

}  // namespace

std::vector<float> MbTextureMinEigen(const uint8_t* luma, int stride, int width, int height) {
  constexpr int kStep = 4;  // sample spacing, px (16 samples per full cell)
  const int cols = MbCount(width), rows = MbCount(height);
  std::vector<float> out(static_cast<size_t>(cols) * rows, 0.0f);
  if (luma == nullptr || width < 3 || height < 3) return out;
  std::vector<TensorSums> sums(cols);
  for (int r = 0; r < rows; ++r) {
    std::fill(sums.begin(), sums.end(), TensorSums{});
    const int y_end = std::min(height, (r + 1) * kMbSizePx);
    for (int y = r * kMbSizePx + 1; y < y_end; y += kStep) {
      const uint8_t* row = luma + static_cast<ptrdiff_t>(y) * stride;
      const uint8_t* up = row - stride;
      const uint8_t* down = luma + static_cast<ptrdiff_t>(std::min(y + 1, height - 1)) * stride;
      for (int c = 0; c < cols; ++c) {
        // Samples x = 16 c + 1, + 5, ...; the one at x = width - 1 (if any)
        // clamps its right neighbour.
        const int x_end = std::min(width - 1, (c + 1) * kMbSizePx);
        TensorSums& s = sums[c];
        int x = c * kMbSizePx + 1;
        for (; x < x_end; x += kStep) s.Add(row[x + 1] - row[x - 1], down[x] - up[x]);
        if (x == width - 1) s.Add(row[x] - row[x - 1], down[x] - up[x]);
      }
    }
    for (int c = 0; c < cols; ++c) out[static_cast<size_t>(r) * cols + c] = sums[c].MinEigen();
  }
  return out;
}

}  // namespace slapse
