#include "core/mv/mb_texture.h"

#include <algorithm>
#include <cmath>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

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

#if defined(__SSE2__)
// The four samples x = x0 + 1, + 5, + 9, + 13 of one sample row at once, for
// a cell whose pixels x0 .. x0 + 15 are all inside the row: gx = I(x+1) -
// I(x-1) are the differences of the even bytes 0 .. 14 in pairs, gy = down(x)
// - up(x) those of the bytes 1, 5, 9, 13. Integer sums, so the same as Add
// per sample.
void AddFourSamples(const uint8_t* row, const uint8_t* up, const uint8_t* down, TensorSums* s) {
  const __m128i low_byte = _mm_set1_epi16(0x00FF);
  const __m128i low_half = _mm_set1_epi32(0x0000FFFF);
  const __m128i r = _mm_loadu_si128(reinterpret_cast<const __m128i*>(row));
  const __m128i u = _mm_loadu_si128(reinterpret_cast<const __m128i*>(up));
  const __m128i d = _mm_loadu_si128(reinterpret_cast<const __m128i*>(down));
  // Even bytes as 16-bit lanes; per 32-bit lane k: I(x0 + 4k) low, I(x0 + 4k + 2) high.
  const __m128i even = _mm_and_si128(r, low_byte);
  const __m128i gx = _mm_sub_epi32(_mm_srli_epi32(even, 16), _mm_and_si128(even, low_half));
  // Odd bytes as 16-bit lanes; per 32-bit lane k the low one is byte 4k + 1.
  const __m128i u1 = _mm_and_si128(_mm_srli_epi16(u, 8), low_half);
  const __m128i d1 = _mm_and_si128(_mm_srli_epi16(d, 8), low_half);
  const __m128i gy = _mm_sub_epi32(d1, u1);
  // |g| <= 255: each 32-bit lane's low 16 bits hold it (two's complement);
  // with the high half cleared, madd gives the products per lane.
  const __m128i gx16 = _mm_and_si128(gx, low_half);
  const __m128i gy16 = _mm_and_si128(gy, low_half);
  auto sum4 = [](__m128i v) {
    v = _mm_add_epi32(v, _mm_shuffle_epi32(v, _MM_SHUFFLE(1, 0, 3, 2)));
    v = _mm_add_epi32(v, _mm_shuffle_epi32(v, _MM_SHUFFLE(2, 3, 0, 1)));
    return _mm_cvtsi128_si32(v);
  };
  s->xx += sum4(_mm_madd_epi16(gx16, gx16));
  s->xy += sum4(_mm_madd_epi16(gx16, gy16));
  s->yy += sum4(_mm_madd_epi16(gy16, gy16));
  s->n += 4;
}
#endif

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
        // Samples x = 16 c + 1, + 5, ...; the one at x = width - 1 (if any,
        // and in this cell) clamps its right neighbour.
        const int x_end = std::min(width - 1, (c + 1) * kMbSizePx);
        TensorSums& s = sums[c];
        int x = c * kMbSizePx + 1;
#if defined(__SSE2__)
        // A cell whose 16 pixels are inside the row takes all four samples.
        if ((c + 1) * kMbSizePx <= width) {
          AddFourSamples(row + x - 1, up + x - 1, down + x - 1, &s);
          x += 4 * kStep;
        }
#endif
        for (; x < x_end; x += kStep) s.Add(row[x + 1] - row[x - 1], down[x] - up[x]);
        if (x == width - 1 && x < (c + 1) * kMbSizePx) s.Add(row[x] - row[x - 1], down[x] - up[x]);
      }
    }
    for (int c = 0; c < cols; ++c) out[static_cast<size_t>(r) * cols + c] = sums[c].MinEigen();
  }
  return out;
}

}  // namespace slapse
