// Procedural textures of the simulated street.
//
// A texture is a deterministic function of texture coordinates (u, v) in
// metres (see lab/sim/scene.h), evaluated on regular sample grids. Each
// sample is box-filtered over its footprint (the grid step), so a texture can
// be made directly at a coarse mip level and stays consistent with its finer
// levels; the renderer builds the remaining levels with cv::pyrDown. Noise is
// hashed from lattice coordinates in metres, so neighbouring tiles join
// without seams and any tile can be remade alone.
#pragma once

#include <opencv2/core.hpp>

#include "lab/sim/scene.h"

namespace slapse {

// Sample (i, j) lies at u = u0_m + i * step_m, v = v0_m + j * step_m.
struct SampleGrid {
  double u0_m = 0.0, v0_m = 0.0;
  double step_m = 0.02;  // spacing and footprint of a sample
  int width = 0, height = 0;
};

// Evaluates texture `texture` of `scene` on `grid`: CV_8UC3, BGR.
cv::Mat GenerateTexture(const Scene& scene, int texture, const SampleGrid& grid);

// Fraction of the interval [x - fw/2, x + fw/2] inside [a, b].
inline double IntervalCoverage(double x, double a, double b, double fw) {
  const double lo = x - 0.5 * fw > a ? x - 0.5 * fw : a;
  const double hi = x + 0.5 * fw < b ? x + 0.5 * fw : b;
  return hi > lo ? (hi - lo) / fw : 0.0;
}
// Fraction of [x - fw/2, x + fw/2] inside the stripes [k * period, k * period + width).
double StripeCoverage(double x, double period, double width, double fw);

}  // namespace slapse
