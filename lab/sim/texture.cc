#include "lab/sim/texture.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "lab/sim/random.h"

namespace slapse {

double StripeCoverage(double x, double period, double width, double fw) {
  // F(x) = measure of stripes in [0, x] (an antiderivative of the stripe indicator).
  auto f = [&](double y) {
    const double k = std::floor(y / period);
    return k * width + std::min(y - k * period, width);
  };
  return (f(x + 0.5 * fw) - f(x - 0.5 * fw)) / fw;
}

namespace {

using cv::Vec3f;

inline float Clamp01(float x) { return x < 0.0f ? 0.0f : (x > 1.0f ? 1.0f : x); }
inline Vec3f Mix(const Vec3f& a, const Vec3f& b, float t) { return a + (b - a) * t; }
inline float Smooth(float t) { return t * t * (3.0f - 2.0f * t); }

// Sample positions and index ranges of a grid.
struct Grid {
  explicit Grid(const SampleGrid& grid) : g(grid) {}
  double U(int i) const { return g.u0_m + i * g.step_m; }
  double V(int j) const { return g.v0_m + j * g.step_m; }
  // Samples whose footprint overlaps [a, b] along u (resp. v); empty if i0 > i1.
  void RangeU(double a, double b, int* i0, int* i1) const { Range(a, b, g.u0_m, g.width, i0, i1); }
  void RangeV(double a, double b, int* j0, int* j1) const { Range(a, b, g.v0_m, g.height, j0, j1); }
  void Range(double a, double b, double o, int n, int* k0, int* k1) const {
    const double lo = std::ceil((a - 0.5 * g.step_m - o) / g.step_m);
    const double hi = std::floor((b + 0.5 * g.step_m - o) / g.step_m);
    *k0 = static_cast<int>(std::max(lo, 0.0));
    *k1 = static_cast<int>(std::min(hi, static_cast<double>(n - 1)));
  }
  const SampleGrid& g;
};

// Adds amplitude * smooth value noise (lattice cells cell_u x cell_v metres,
// lattice values uniform in [-1, 1]) to `acc`. Band-limited: octaves finer than
// two samples fade out, as a box filter of the sample footprint would do.
void AddValueNoise(const SampleGrid& g, uint64_t seed, double cell_u, double cell_v,
                   float amplitude, cv::Mat1f* acc) {
  const float att = Clamp01(static_cast<float>(std::min(cell_u, cell_v) / g.step_m - 1.0));
  if (att <= 0.0f) return;
  amplitude *= att;
  const int64_t ix0 = static_cast<int64_t>(std::floor(g.u0_m / cell_u));
  const int64_t iy0 = static_cast<int64_t>(std::floor(g.v0_m / cell_v));
  const int64_t ix1 =
      static_cast<int64_t>(std::floor((g.u0_m + (g.width - 1) * g.step_m) / cell_u)) + 1;
  const int64_t iy1 =
      static_cast<int64_t>(std::floor((g.v0_m + (g.height - 1) * g.step_m) / cell_v)) + 1;
  const int nx = static_cast<int>(ix1 - ix0 + 1), ny = static_cast<int>(iy1 - iy0 + 1);
  std::vector<float> lattice(static_cast<size_t>(nx) * ny);
  for (int y = 0; y < ny; ++y) {
    for (int x = 0; x < nx; ++x) {
      lattice[static_cast<size_t>(y) * nx + x] = HashSigned(Hash2(seed, ix0 + x, iy0 + y));
    }
  }
  std::vector<int> cx(g.width);
  std::vector<float> wx(g.width);
  for (int i = 0; i < g.width; ++i) {
    const double f = (g.u0_m + i * g.step_m) / cell_u - static_cast<double>(ix0);
    const int k = std::clamp(static_cast<int>(std::floor(f)), 0, nx - 2);
    cx[i] = k;
    wx[i] = Smooth(Clamp01(static_cast<float>(f - k)));
  }
  for (int j = 0; j < g.height; ++j) {
    const double f = (g.v0_m + j * g.step_m) / cell_v - static_cast<double>(iy0);
    const int k = std::clamp(static_cast<int>(std::floor(f)), 0, ny - 2);
    const float wy = Smooth(Clamp01(static_cast<float>(f - k)));
    const float* r0 = &lattice[static_cast<size_t>(k) * nx];
    const float* r1 = r0 + nx;
    float* out = acc->ptr<float>(j);
    for (int i = 0; i < g.width; ++i) {
      const int c = cx[i];
      const float a = r0[c] + (r0[c + 1] - r0[c]) * wx[i];
      const float b = r1[c] + (r1[c + 1] - r1[c]) * wx[i];
      out[i] += amplitude * (a + (b - a) * wy);
    }
  }
}

// Adds per-texel white noise of standard deviation `sigma` at level 0; a
// coarser sample averages (step/texel)^2 texels, so its deviation shrinks.
void AddWhiteNoise(const SampleGrid& g, uint64_t seed, double texel_m, float sigma,
                   cv::Mat1f* acc) {
  const double ratio = texel_m / g.step_m;
  const int level = static_cast<int>(std::lround(std::log2(1.0 / std::min(ratio, 1.0))));
  const float amp = sigma * 1.7320508f * static_cast<float>(std::min(ratio, 1.0));
  for (int j = 0; j < g.height; ++j) {
    const int64_t b = std::llround((g.v0_m + j * g.step_m) / texel_m - 0.5);
    float* out = acc->ptr<float>(j);
    for (int i = 0; i < g.width; ++i) {
      const int64_t a = std::llround((g.u0_m + i * g.step_m) / texel_m - 0.5);
      out[i] += amp * HashSigned(Hash3(seed, a, b, level));
    }
  }
}

// Blends colour_fn(u, v) over the rectangle [u0, u1] x [v0, v1] with box-filtered coverage.
template <typename ColourFn>
void BlendRect(const Grid& grid, double u0, double u1, double v0, double v1, float opacity,
               cv::Mat3f* img, ColourFn colour_fn) {
  int i0, i1, j0, j1;
  grid.RangeU(u0, u1, &i0, &i1);
  grid.RangeV(v0, v1, &j0, &j1);
  const double st = grid.g.step_m;
  for (int j = j0; j <= j1; ++j) {
    const double v = grid.V(j);
    const float cv_ = static_cast<float>(IntervalCoverage(v, v0, v1, st));
    if (cv_ <= 0.0f) continue;
    Vec3f* row = img->ptr<Vec3f>(j);
    for (int i = i0; i <= i1; ++i) {
      const double u = grid.U(i);
      const float c = cv_ * static_cast<float>(IntervalCoverage(u, u0, u1, st)) * opacity;
      if (c <= 0.0f) continue;
      row[i] = Mix(row[i], colour_fn(u, v), c);
    }
  }
}

void FillRect(const Grid& grid, double u0, double u1, double v0, double v1, const Vec3f& colour,
              cv::Mat3f* img) {
  BlendRect(grid, u0, u1, v0, v1, 1.0f, img, [&](double, double) { return colour; });
}

// Distance from p to the segment ab.
inline double SegmentDistance(double px, double py, double ax, double ay, double bx, double by) {
  const double dx = bx - ax, dy = by - ay;
  const double len2 = dx * dx + dy * dy;
  double t = len2 > 0 ? ((px - ax) * dx + (py - ay) * dy) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  const double ex = px - ax - t * dx, ey = py - ay - t * dy;
  return std::sqrt(ex * ex + ey * ey);
}

// ---------------------------------------------------------------- facades

struct WindowLook {
  float darkness;    // 0..255 base of the glass
  float reflection;  // 0..255 peak of the sky reflection
  float phase;
  bool curtain;
  bool curtain_left;
  float curtain_frac;
  Vec3f fabric;
};

WindowLook MakeWindowLook(uint64_t h) {
  WindowLook w;
  w.darkness = 28.0f + 55.0f * HashUnit(Mix64(h ^ 1));
  w.reflection = 15.0f + 55.0f * HashUnit(Mix64(h ^ 2));
  w.phase = 6.283f * HashUnit(Mix64(h ^ 3));
  w.curtain = HashUnit(Mix64(h ^ 4)) < 0.4f;
  w.curtain_left = HashUnit(Mix64(h ^ 5)) < 0.5f;
  w.curtain_frac = 0.25f + 0.3f * HashUnit(Mix64(h ^ 6));
  const float f = 140.0f + 90.0f * HashUnit(Mix64(h ^ 7));
  w.fabric = Vec3f(f * (0.75f + 0.25f * HashUnit(Mix64(h ^ 8))), f * 0.95f, f);
  return w;
}

// Glass colour at local coordinates x (0 left .. 1 right), y (0 bottom .. 1 top).
Vec3f GlassColour(const WindowLook& w, double x, double y, double u) {
  Vec3f c(w.darkness * 1.25f, w.darkness * 1.08f, w.darkness * 0.95f);
  const float streak = 0.5f + 0.5f * std::sin(static_cast<float>(5.0 * (x + 0.6 * y)) + w.phase);
  const float r = w.reflection * static_cast<float>(0.35 + 0.65 * y) * streak;
  c += Vec3f(r, 0.95f * r, 0.85f * r);
  if (w.curtain && (w.curtain_left ? x < w.curtain_frac : x > 1.0 - w.curtain_frac)) {
    const float fold = 0.8f + 0.2f * std::sin(static_cast<float>(2.0 * M_PI * u / 0.09));
    c = w.fabric * fold;
  }
  return c;
}

// A framed window with sill; (uc, zb) bottom centre; z = height above ground.
void DrawWindow(const Grid& grid, const FacadeStyle& f, double uc, double zb, double ww, double wh,
                uint64_t h, bool stone_lintel, cv::Mat3f* img) {
  const double H = f.height_m;
  auto vz = [H](double z) { return H - z; };
  const double zt = zb + wh, fw = 0.07;
  const Vec3f sill = f.trim_bgr * 1.04f;
  FillRect(grid, uc - 0.5 * ww - 0.06, uc + 0.5 * ww + 0.06, vz(zb), vz(zb - 0.08), sill, img);
  if (stone_lintel) {
    FillRect(grid, uc - 0.5 * ww - 0.06, uc + 0.5 * ww + 0.06, vz(zt + 0.14), vz(zt),
             Vec3f(178, 188, 196), img);
  }
  FillRect(grid, uc - 0.5 * ww, uc + 0.5 * ww, vz(zt), vz(zb), f.trim_bgr, img);
  const WindowLook look = MakeWindowLook(h);
  const double gu0 = uc - 0.5 * ww + fw, gu1 = uc + 0.5 * ww - fw;
  const double gz0 = zb + fw, gz1 = zt - fw;
  BlendRect(grid, gu0, gu1, vz(gz1), vz(gz0), 1.0f, img, [&](double u, double v) {
    return GlassColour(look, (u - gu0) / (gu1 - gu0), (H - v - gz0) / (gz1 - gz0), u);
  });
  if (f.mullions) {
    const Vec3f frame = f.trim_bgr * 0.95f;
    FillRect(grid, uc - 0.025, uc + 0.025, vz(gz1), vz(gz0), frame, img);
    const double zm = gz0 + 0.68 * (gz1 - gz0);
    FillRect(grid, gu0, gu1, vz(zm + 0.025), vz(zm - 0.025), frame, img);
  }
}

// Glyph-like strokes on shop signs: coverage of the glyph ink at (x, y),
// local to the sign's text band (x from its left, y from its bottom, metres).
float GlyphCoverage(uint64_t seed, double x, double y, double band_h, double st) {
  const double cell_w = 0.72 * band_h;
  const int64_t cell = static_cast<int64_t>(std::floor(x / cell_w));
  const uint64_t h = Hash2(seed, cell, 0x61);
  if (HashUnit(h) < 0.15f) return 0.0f;  // space between words
  const double lx = x - cell * cell_w;
  const int strokes = 2 + static_cast<int>((h >> 8) % 3);
  const double radius = 0.06 * band_h;
  float cov = 0.0f;
  for (int k = 0; k < strokes; ++k) {
    const uint64_t hs = Hash2(h, k, 0x73);
    const int p0 = static_cast<int>(hs % 12), p1 = static_cast<int>((hs >> 8) % 12);
    const int q1 = p1 == p0 ? (p1 + 5) % 12 : p1;
    const double ax = (0.15 + 0.35 * (p0 % 3)) * cell_w, ay = (0.1 + 0.2667 * (p0 / 3)) * band_h;
    const double bx = (0.15 + 0.35 * (q1 % 3)) * cell_w, by = (0.1 + 0.2667 * (q1 / 3)) * band_h;
    const double d = SegmentDistance(lx, y, ax, ay, bx, by);
    cov = std::max(cov, Clamp01(static_cast<float>((radius - d) / st + 0.5)));
  }
  return cov;
}

// The wall's material: brick courses with mortar joints, or plain render.
void DrawWallMaterial(const FacadeStyle& f, const Grid& grid, const SampleGrid& g, uint64_t seed,
                      cv::Mat3f* img) {
  const double st = g.step_m, H = f.height_m;
  const double bh = 0.075, bl = 0.225, mortar = 0.012;
  const float brick_detail = static_cast<float>(std::min(1.0, std::sqrt(bh * bl) / st));
  for (int j = 0; j < g.height; ++j) {
    const double z = H - grid.V(j);
    Vec3f* row = img->ptr<Vec3f>(j);
    const int64_t course = static_cast<int64_t>(std::floor(z / bh));
    const double off = (course & 1) ? 0.5 * bl : 0.0;
    const double mh = StripeCoverage(z, bh, mortar, st);
    for (int i = 0; i < g.width; ++i) {
      const double u = grid.U(i);
      if (f.brick) {
        const int64_t bi = static_cast<int64_t>(std::floor((u + off) / bl));
        const uint64_t hb = Hash2(seed ^ 0xB81C, bi, course);
        const float shade = 1.0f + 0.2f * brick_detail * HashSigned(hb);
        const float red = 1.0f + 0.06f * brick_detail * HashSigned(Mix64(hb));
        Vec3f brick = f.wall_bgr * shade;
        brick[2] *= red;
        const double mv = StripeCoverage(u + off, bl, mortar, st);
        const float m = static_cast<float>(1.0 - (1.0 - mh) * (1.0 - mv));
        row[i] = Mix(brick, f.mortar_bgr, m);
      } else {
        row[i] = f.wall_bgr;
      }
    }
  }
}

// A shop's ground floor: display windows with goods, a glass door and a
// sign board with glyphs.
void DrawShopFront(const FacadeStyle& f, const Grid& grid, double st, uint64_t seed,
                   cv::Mat3f* img) {
  const double H = f.height_m, gf = f.ground_floor_m;
  auto vz = [H](double z) { return H - z; };
  const Vec3f metal(52, 50, 48);
  // Display windows left and right of the door, split into panes.
  const double z0 = 0.5, z1 = gf - 1.2;
  const double spans[2][2] = {{f.sign_u0_m + 0.15, f.door_u_m - 0.2},
                              {f.door_u_m + f.door_w_m + 0.2, f.sign_u1_m - 0.15}};
  for (const auto& span : spans) {
    if (span[1] - span[0] < 0.6) continue;
    FillRect(grid, span[0], span[1], vz(z1), vz(z0), metal, img);
    const int panes = std::max(1, static_cast<int>(std::round((span[1] - span[0]) / 2.0)));
    const double pw = (span[1] - span[0]) / panes;
    for (int p = 0; p < panes; ++p) {
      const double a = span[0] + p * pw + 0.06, b = span[0] + (p + 1) * pw - 0.06;
      const WindowLook look = MakeWindowLook(Hash3(seed, -1, p, static_cast<int64_t>(a * 100)));
      BlendRect(grid, a, b, vz(z1 - 0.06), vz(z0 + 0.06), 1.0f, img, [&](double u, double v) {
        const double z = H - v;
        Vec3f c = GlassColour(look, (u - a) / (b - a), (z - z0) / (z1 - z0), u);
        // Goods on shelves: small coloured blocks behind the glass.
        if (z < z0 + 0.55 * (z1 - z0)) {
          const uint64_t hg = Hash2(seed ^ 0x600D, static_cast<int64_t>(std::floor(u / 0.22)),
                                    static_cast<int64_t>(std::floor(z / 0.3)));
          const Vec3f goods(60 + 150 * HashUnit(hg), 60 + 150 * HashUnit(Mix64(hg)),
                            60 + 150 * HashUnit(Mix64(hg ^ 9)));
          c = Mix(c, goods, 0.55f);
        }
        return c;
      });
    }
  }
  // Glass door.
  FillRect(grid, f.door_u_m, f.door_u_m + f.door_w_m, vz(2.3), vz(0.0), metal, img);
  const WindowLook door_look = MakeWindowLook(Hash2(seed, 0xD00, 1));
  BlendRect(grid, f.door_u_m + 0.07, f.door_u_m + f.door_w_m - 0.07, vz(2.23), vz(0.1), 1.0f, img,
            [&](double u, double v) {
              return GlassColour(door_look, (u - f.door_u_m) / f.door_w_m, (H - v) / 2.3, u);
            });
  // Sign board with a frame and glyphs.
  const double s0 = gf - 0.95, s1 = gf - 0.2;
  FillRect(grid, f.sign_u0_m - 0.05, f.sign_u1_m + 0.05, vz(s1 + 0.05), vz(s0 - 0.05),
           f.trim_bgr * 0.5f, img);
  const double t0 = s0 + 0.12, t1 = s1 - 0.12;
  BlendRect(grid, f.sign_u0_m, f.sign_u1_m, vz(s1), vz(s0), 1.0f, img, [&](double u, double v) {
    const double z = H - v;
    Vec3f c = f.sign_bgr * static_cast<float>(0.9 + 0.2 * (z - s0) / (s1 - s0));
    if (z > t0 - st && z < t1 + st && u > f.sign_u0_m + 0.15 && u < f.sign_u1_m - 0.15) {
      const float ink = GlyphCoverage(seed ^ 0x5161, u - f.sign_u0_m - 0.15, z - t0, t1 - t0, st);
      c = Mix(c, f.glyph_bgr, ink);
    }
    return c;
  });
}

void FacadeTexture(const Scene& scene, const TextureDesc& d, const SampleGrid& g, cv::Mat3f* img) {
  const FacadeStyle& f = scene.facades[d.style];
  const Grid grid(g);
  const double st = g.step_m, H = f.height_m, W = f.width_m;
  const uint64_t seed = d.seed;
  auto vz = [H](double z) { return H - z; };

  DrawWallMaterial(f, grid, g, seed, img);
  // Plinth, cornices, coping.
  FillRect(grid, -1.0, W + 1.0, vz(0.55), vz(-1.0), Vec3f(118, 124, 130), img);
  if (f.cornices) {
    FillRect(grid, -1.0, W + 1.0, vz(f.ground_floor_m + 0.15), vz(f.ground_floor_m - 0.1),
             f.trim_bgr, img);
    for (double zc = f.ground_floor_m + f.floor_m; zc < H - 1.0; zc += f.floor_m) {
      FillRect(grid, -1.0, W + 1.0, vz(zc + 0.06), vz(zc - 0.06), f.trim_bgr * 0.97f, img);
    }
  }
  FillRect(grid, -1.0, W + 1.0, vz(H + 1.0), vz(H - 0.35), f.trim_bgr * 0.85f, img);

  // Upper floors: a regular grid of windows.
  const double u_lo = g.u0_m - st, u_hi = g.u0_m + (g.width + 1) * st;
  const double ww = f.window_w_m, wh = f.window_h_m;
  const int k_lo =
      std::max(0, static_cast<int>(std::floor((u_lo - f.window_u0_m - ww) / f.window_pitch_m)));
  const int k_hi = static_cast<int>(std::ceil((u_hi - f.window_u0_m + ww) / f.window_pitch_m));
  for (int fl = 1;; ++fl) {
    const double zb = f.ground_floor_m + (fl - 1) * f.floor_m + f.sill_m;
    if (zb + wh > H - 0.5) break;
    const double v_top = vz(zb + wh + 0.2), v_bottom = vz(zb - 0.1);
    if (v_bottom < g.v0_m - st || v_top > g.v0_m + (g.height + 1) * st) continue;
    for (int k = k_lo; k <= k_hi; ++k) {
      const double uc = f.window_u0_m + k * f.window_pitch_m;
      if (uc - 0.5 * ww < 0.3 || uc + 0.5 * ww > W - 0.3) continue;
      DrawWindow(grid, f, uc, zb, ww, wh, Hash3(seed, fl, k, 0x77), f.brick, img);
    }
  }

  // Ground floor.
  const double gf = f.ground_floor_m;
  const double door_c = f.door_u_m + 0.5 * f.door_w_m;
  if (f.shop) {
    DrawShopFront(f, grid, st, seed, img);
  } else {
    // Wooden door in a frame.
    FillRect(grid, f.door_u_m - 0.08, f.door_u_m + f.door_w_m + 0.08, vz(2.38), vz(0.0), f.trim_bgr,
             img);
    const uint64_t hd = Hash2(seed, 0xD00, 2);
    const Vec3f wood(35 + 25 * HashUnit(hd), 55 + 30 * HashUnit(Mix64(hd)),
                     85 + 40 * HashUnit(hd ^ 5));
    BlendRect(grid, f.door_u_m, f.door_u_m + f.door_w_m, vz(2.3), vz(0.0), 1.0f, img,
              [&](double u, double) {
                const double panel =
                    StripeCoverage(u - f.door_u_m - 0.1, 0.5 * f.door_w_m, 0.04, st);
                return wood * static_cast<float>(1.0 - 0.35 * panel);
              });
    // Ground-floor windows where the door is not.
    const double zb = 1.0, h0 = std::min(wh, gf - 1.6);
    if (h0 > 0.6) {
      for (int k = k_lo; k <= k_hi; ++k) {
        const double uc = f.window_u0_m + k * f.window_pitch_m;
        if (uc - 0.5 * ww < 0.3 || uc + 0.5 * ww > W - 0.3) continue;
        if (std::abs(uc - door_c) < 0.5 * (ww + f.door_w_m) + 0.25) continue;
        DrawWindow(grid, f, uc, zb, ww, h0, Hash3(seed, 0, k, 0x77), f.brick, img);
      }
    }
  }

  // Band-limited noise over everything, then the orientation shading.
  cv::Mat1f lum(g.height, g.width, 0.0f);
  AddValueNoise(g, seed ^ 0x101, 3.0, 3.0, f.brick ? 8.0f : 14.0f, &lum);
  AddValueNoise(g, seed ^ 0x102, 0.7, 0.7, 8.0f, &lum);
  AddValueNoise(g, seed ^ 0x103, 0.18, 0.18, 7.0f, &lum);
  AddValueNoise(g, seed ^ 0x104, 0.06, 0.06, 6.0f, &lum);
  AddWhiteNoise(g, seed ^ 0x105, d.texel_m, 7.0f, &lum);
  for (int j = 0; j < g.height; ++j) {
    Vec3f* row = img->ptr<Vec3f>(j);
    const float* n = lum.ptr<float>(j);
    for (int i = 0; i < g.width; ++i) row[i] = (row[i] + Vec3f(n[i], n[i], n[i])) * d.gain;
  }
}

// ---------------------------------------------------------------- road

// Repair patches (rectangles of another tone with a dark seam) and cracks
// (thin dark segments), hashed per cell of the road's (u, v) plane: a
// brightness factor for the asphalt at (u, v).
float AsphaltWear(uint64_t seed, double u, double v, double st) {
  float factor = 1.0f;
  {
    const double cell = 4.0;
    const int64_t cu = static_cast<int64_t>(std::floor(u / cell));
    const int64_t cv = static_cast<int64_t>(std::floor(v / cell));
    const uint64_t h = Hash2(seed ^ 0x9A7C4, cu, cv);
    if (HashUnit(h) < 0.25f) {
      const double w = 0.8 + 1.7 * HashUnit(Mix64(h ^ 1)), hh = 0.8 + 1.7 * HashUnit(Mix64(h ^ 2));
      const double u0 = cu * cell + (cell - w) * HashUnit(Mix64(h ^ 3));
      const double v0 = cv * cell + (cell - hh) * HashUnit(Mix64(h ^ 4));
      const double in = IntervalCoverage(u, u0, u0 + w, st) * IntervalCoverage(v, v0, v0 + hh, st);
      const double inner = IntervalCoverage(u, u0 + 0.03, u0 + w - 0.03, st) *
                           IntervalCoverage(v, v0 + 0.03, v0 + hh - 0.03, st);
      const float tone = 0.85f + 0.3f * HashUnit(Mix64(h ^ 5));
      factor *= static_cast<float>(1.0 + (tone - 1.0) * inner - 0.35 * (in - inner));
    }
  }
  {
    const double cell = 1.5;
    const int64_t cu = static_cast<int64_t>(std::floor(u / cell));
    const int64_t cv = static_cast<int64_t>(std::floor(v / cell));
    const uint64_t h = Hash2(seed ^ 0xC4AC, cu, cv);
    if (HashUnit(h) < 0.2f) {
      const double ax = (cu + HashUnit(Mix64(h ^ 1))) * cell,
                   ay = (cv + HashUnit(Mix64(h ^ 2))) * cell;
      const double bx = (cu + HashUnit(Mix64(h ^ 3))) * cell,
                   by = (cv + HashUnit(Mix64(h ^ 4))) * cell;
      const double dist = SegmentDistance(u, v, ax, ay, bx, by);
      const float cov = Clamp01(static_cast<float>((0.006 - dist) / st + 0.5));
      factor *= 1.0f - 0.55f * cov;
    }
  }
  return factor;
}

// The road's curvilinear coordinates (s along the centreline, lateral
// offset) on a grid of every kRoadGridStep-th sample of a tile (+ 1 beyond),
// for bilinear interpolation per sample.
constexpr int kRoadGridStep = 8;
struct RoadGrid {
  int cols = 0, rows = 0;
  std::vector<double> s, lateral;  // row-major
};

RoadGrid MakeRoadGrid(const RoadStyle& r, const Centreline& cl, const SampleGrid& g,
                      const Eigen::Vector2d& centre, double tile_r) {
  const double st = g.step_m;
  const int kStep = kRoadGridStep;
  RoadGrid grid;
  grid.cols = (g.width - 1) / kStep + 2;
  grid.rows = (g.height - 1) / kStep + 2;
  const double reach = std::max(r.strip_left_m, r.strip_right_m) + 10.0;
  int seg_lo = -1, seg_hi = -2;
  const auto& segs = cl.segments();
  for (int k = 0; k < static_cast<int>(segs.size()); ++k) {
    const double half = 0.5 * segs[k].length_m;
    if ((cl.Point(segs[k].s0_m + half) - centre).norm() < half + tile_r + reach) {
      if (seg_lo < 0) seg_lo = k;
      seg_hi = k;
    }
  }
  grid.s.resize(static_cast<size_t>(grid.cols) * grid.rows);
  grid.lateral.resize(grid.s.size());
  for (int y = 0; y < grid.rows; ++y) {
    for (int x = 0; x < grid.cols; ++x) {
      const double u = g.u0_m + x * kStep * st, v = g.v0_m + y * kStep * st;
      const Eigen::Vector2d p = r.origin_xy + u * r.u_xy + v * r.v_xy;
      double s = 0, l = 1e9;
      if (seg_lo >= 0) cl.Project(p, &s, &l, seg_lo, seg_hi);
      grid.s[static_cast<size_t>(y) * grid.cols + x] = s;
      grid.lateral[static_cast<size_t>(y) * grid.cols + x] = l;
    }
  }
  return grid;
}

// Coverage of paint at road coordinates (s, l): the dashed centre line, the
// edge lines, crosswalks with their stop lines, and arrows.
float RoadMarkings(const RoadStyle& r, double s, double l, double st) {
  const double hw = r.half_width_m, al = std::abs(l);
  float m = 0.0f;
  for (double x : r.dash_lateral_m) {
    m = std::max(m, static_cast<float>(IntervalCoverage(l - x, -0.06, 0.06, st) *
                                       StripeCoverage(s, r.dash_period_m, r.dash_length_m, st)));
  }
  for (double x : r.solid_lateral_m) {
    m = std::max(m, static_cast<float>(IntervalCoverage(l - x, -0.075, 0.075, st)));
  }
  m = std::max(m, static_cast<float>(IntervalCoverage(al, hw - 0.45, hw - 0.3, st)));
  if (r.stall_lateral_max_m > r.stall_lateral_min_m) {  // parking stalls across the lot
    const double in = IntervalCoverage(al, r.stall_lateral_min_m, r.stall_lateral_max_m, st);
    m = std::max(m, static_cast<float>(in * StripeCoverage(s, r.stall_period_m, 0.12, st)));
    m = std::max(m, static_cast<float>(IntervalCoverage(s, r.s_begin_m, r.s_end_m, st) *
                                       IntervalCoverage(al, r.stall_lateral_max_m - 0.12,
                                                        r.stall_lateral_max_m, st)));
  }
  for (double sc : r.crosswalk_s_m) {
    if (s < sc - 3.0 || s > sc + 7.0) continue;
    const double inside = IntervalCoverage(l, -hw + 0.3, hw - 0.3, st);
    m = std::max(m, static_cast<float>(IntervalCoverage(s, sc, sc + 4.0, st) * inside *
                                       StripeCoverage(l + hw - 0.3, 1.0, 0.5, st)));
    m = std::max(m, static_cast<float>(IntervalCoverage(s, sc - 2.0, sc - 1.6, st) *
                                       IntervalCoverage(l, -hw + 0.3, -0.1, st)));
    m = std::max(m, static_cast<float>(IntervalCoverage(s, sc + 5.6, sc + 6.0, st) *
                                       IntervalCoverage(l, 0.1, hw - 0.3, st)));
  }
  for (const auto& a : r.arrows) {
    const double dir = a.forward ? 1.0 : -1.0;
    const double ds = (s - a.s_m) * dir, dl = (l - a.lateral_m) * dir;
    if (ds < -0.5 || ds > 5.0 || std::abs(dl) > 0.6) continue;
    float am = static_cast<float>(IntervalCoverage(ds, 0.0, 3.0, st) *
                                  IntervalCoverage(dl, -0.08, 0.08, st));
    if (ds > 2.9 && ds < 4.3) {
      const double half = 0.4 * std::clamp((4.2 - ds) / 1.2, 0.0, 1.0);
      am = std::max(am, static_cast<float>(IntervalCoverage(dl, -half, half, st) *
                                           IntervalCoverage(ds, 3.0, 4.2, st)));
    }
    m = std::max(m, am);
  }
  return m;
}

// A manhole cover over colour *c at world point p: a dark disc with a grid
// pattern and a rim.
void DrawManhole(const RoadStyle::Manhole& mh, const Eigen::Vector2d& p, double st, Vec3f* c) {
  const double dist = (p - mh.xy).norm();
  const float cov = Clamp01(static_cast<float>((mh.radius_m - dist) / st + 0.5));
  if (cov <= 0.0f) return;
  const Eigen::Vector2d q = p - mh.xy;
  const double grid_cov = 1.0 - (1.0 - StripeCoverage(q.x(), 0.06, 0.02, st)) *
                                    (1.0 - StripeCoverage(q.y(), 0.06, 0.02, st));
  const bool rim = dist > mh.radius_m - 0.05;
  const Vec3f metal = rim ? Vec3f(70, 72, 74)
                          : Vec3f(50, 52, 54) + Vec3f(30, 30, 30) * static_cast<float>(grid_cov);
  *c = Mix(*c, metal, cov);
}

// Beyond a road without curbs, q metres from the asphalt's edge: a gravel
// shoulder, then the field (furrows in a fixed world direction, patches).
Vec3f VergeColour(const RoadStyle& r, double q, double u, double v, double st, float hu,
                  float patch) {
  if (q < r.shoulder_m) {
    const Vec3f gravel(105, 118, 128);
    return gravel * (0.8f + 0.4f * hu);
  }
  const double furrow = StripeCoverage(0.8 * u + 0.6 * v, r.field_row_m, 0.35 * r.field_row_m, st);
  return r.field_bgr * static_cast<float>((1.0 + patch) * (1.0 - 0.3 * furrow)) *
         (0.85f + 0.3f * hu);
}

void RoadTexture(const Scene& scene, const TextureDesc& d, const SampleGrid& g, cv::Mat3f* img) {
  const RoadStyle& r = scene.road;
  const Centreline& cl = scene.centreline;
  const double st = g.step_m, hw = r.half_width_m;
  const uint64_t seed = d.seed;
  auto world = [&](double u, double v) -> Eigen::Vector2d {
    return r.origin_xy + u * r.u_xy + v * r.v_xy;
  };

  // Curvilinear coordinates (s, lateral) on a coarse grid, interpolated per sample.
  const int kStep = kRoadGridStep;
  const Eigen::Vector2d centre = world(g.u0_m + 0.5 * g.width * st, g.v0_m + 0.5 * g.height * st);
  const double tile_r = 0.75 * std::max(g.width, g.height) * st;
  const RoadGrid grid = MakeRoadGrid(r, cl, g, centre, tile_r);
  const int cw = grid.cols, ch = grid.rows;
  const std::vector<double>& cs = grid.s;
  const std::vector<double>& cl_lat = grid.lateral;

  // Noise layers.
  cv::Mat1f lum(g.height, g.width, 0.0f), wear(g.height, g.width, 0.0f);
  AddValueNoise(g, seed ^ 0x201, 2.5, 2.5, 9.0f, &lum);
  AddValueNoise(g, seed ^ 0x208, 1.2, 1.2, 12.0f, &lum);
  AddValueNoise(g, seed ^ 0x202, 0.6, 0.6, 16.0f, &lum);
  AddValueNoise(g, seed ^ 0x203, 0.25, 0.25, 20.0f, &lum);
  AddValueNoise(g, seed ^ 0x207, 0.1, 0.1, 14.0f, &lum);
  AddValueNoise(g, seed ^ 0x204, 0.05, 0.05, 9.0f, &lum);
  AddWhiteNoise(g, seed ^ 0x205, d.texel_m, 12.0f, &lum);
  AddValueNoise(g, seed ^ 0x206, 0.35, 0.35, 1.0f, &wear);
  const float detail = static_cast<float>(std::min(1.0, d.texel_m / st));
  const float speck = detail * detail;

  // Features near this tile.
  std::vector<const RoadStyle::Manhole*> manholes;
  for (const auto& m : r.manholes) {
    if ((m.xy - centre).norm() < tile_r + m.radius_m + 0.1) manholes.push_back(&m);
  }

  const Vec3f asphalt(r.asphalt_bgr), canyon_asphalt(92, 92, 92), curb(165, 168, 170);
  const Vec3f paving(148, 160, 168), joint(92, 96, 100), paint(r.paint_bgr);
  cv::Mat1f field;  // kField verges: patches and clumps
  if (r.verge == RoadStyle::Verge::kField) {
    field = cv::Mat1f(g.height, g.width, 0.0f);
    AddValueNoise(g, seed ^ 0xF1E1, 3.0, 3.0, 0.18f, &field);
    AddValueNoise(g, seed ^ 0xF1E2, 0.3, 0.3, 0.15f, &field);
    AddValueNoise(g, seed ^ 0xF1E3, 0.08, 0.08, 0.12f, &field);
  }
  for (int j = 0; j < g.height; ++j) {
    const double fy = static_cast<double>(j) / kStep;
    const int y0 = std::min(static_cast<int>(fy), ch - 2);
    const double ty = fy - y0;
    Vec3f* row = img->ptr<Vec3f>(j);
    const float* n = lum.ptr<float>(j);
    const float* wr = wear.ptr<float>(j);
    for (int i = 0; i < g.width; ++i) {
      const double fx = static_cast<double>(i) / kStep;
      const int x0 = std::min(static_cast<int>(fx), cw - 2);
      const double tx = fx - x0;
      const size_t k00 = static_cast<size_t>(y0) * cw + x0;
      auto bil = [&](const std::vector<double>& a) {
        return (1 - ty) * ((1 - tx) * a[k00] + tx * a[k00 + 1]) +
               ty * ((1 - tx) * a[k00 + cw] + tx * a[k00 + cw + 1]);
      };
      const double s = bil(cs), l = bil(cl_lat), al = std::abs(l);
      const double u = g.u0_m + i * st, v = g.v0_m + j * st;
      const double strip = l >= 0 ? r.strip_left_m : r.strip_right_m;
      const bool in_street = s >= r.s_begin_m - 0.5 && s <= r.s_end_m + 0.5 && al <= strip + 0.5;
      const uint64_t hs = Hash3(seed ^ 0x5EC, std::llround(u / d.texel_m - 0.5),
                                std::llround(v / d.texel_m - 0.5), 0);
      const float hu = HashUnit(hs);
      Vec3f c;
      if (!in_street || al < hw) {
        c = in_street ? asphalt : canyon_asphalt;
        c *= AsphaltWear(seed, u, v, st);
        // Aggregate: bright and dark specks.
        if (hu < 0.08f) c += Vec3f(60, 60, 60) * speck;
        if (hu > 0.92f) c -= Vec3f(38, 38, 38) * speck;
        if (in_street) {
          // Darker wheel tracks in both lanes.
          const double lane = 0.5 * hw;
          const double tr = std::min({std::abs(al - (lane - 0.8)), std::abs(al - (lane + 0.8))});
          c *= static_cast<float>(1.0 - 0.1 * std::max(0.0, 1.0 - tr / 0.35));
          const float m = RoadMarkings(r, s, l, st);
          if (m > 0.0f) c = Mix(c, paint, m * Clamp01(0.8f + 0.6f * wr[i] - 1.5f * r.paint_wear));
        }
      } else if (r.verge == RoadStyle::Verge::kField) {
        c = VergeColour(r, al - hw, u, v, st, hu, field(j, i));
      } else if (al < hw + r.curb_m) {
        c = curb * static_cast<float>(1.0 - 0.4 * StripeCoverage(s, 1.0, 0.015, st));
      } else {
        const double q = al - hw - r.curb_m;
        const int64_t ks = static_cast<int64_t>(std::floor(s / 0.4));
        const int64_t kl = static_cast<int64_t>(std::floor(q / 0.4)) * (l >= 0 ? 1 : -1);
        const float shade = 1.0f + 0.08f * detail * HashSigned(Hash2(seed ^ 0x5AB, ks, kl));
        const double jt = 1.0 - (1.0 - StripeCoverage(s, 0.4, 0.012, st)) *
                                    (1.0 - StripeCoverage(q, 0.4, 0.012, st));
        c = Mix(paving * shade, joint, static_cast<float>(jt));
      }
      for (const auto* mh : manholes) DrawManhole(*mh, world(u, v), st, &c);
      const float nl = n[i] * r.grain;
      row[i] = (c + Vec3f(nl, nl, nl)) * d.gain;
    }
  }
}

// ---------------------------------------------------------------- background

void BackgroundTexture(const Scene& scene, const TextureDesc& d, const SampleGrid& g,
                       cv::Mat3f* img) {
  const BackgroundStyle& b = scene.backgrounds[d.style];
  const Grid grid(g);
  const double st = g.step_m;
  const Vec3f haze(208, 198, 188);
  for (int j = 0; j < g.height; ++j) {
    const double z = b.top_m - grid.V(j);
    Vec3f* row = img->ptr<Vec3f>(j);
    size_t k = 0;
    for (int i = 0; i < g.width; ++i) {
      const double u = grid.U(i);
      while (k + 1 < b.blocks.size() && u >= b.blocks[k].u1_m) ++k;
      while (k > 0 && u < b.blocks[k].u0_m) --k;
      const BackgroundStyle::Block& blk = b.blocks[k];
      Vec3f c = blk.bgr;
      const double wu = u - blk.u0_m - 0.8, wz = z - 1.2;
      const double cov =
          b.windows ? StripeCoverage(wu, 2.6, 1.3, st) * StripeCoverage(wz, 3.3, 1.5, st) : 0.0;
      if (cov > 0.0) {
        const uint64_t h = Hash3(d.seed, static_cast<int64_t>(std::floor(wu / 2.6)),
                                 static_cast<int64_t>(std::floor(wz / 3.3)), k);
        const Vec3f win = HashUnit(h) < 0.15f ? Vec3f(120, 190, 225) : c * 0.45f;
        c = Mix(c, win, static_cast<float>(cov));
      }
      if (b.windows && z > blk.height_m - 1.0) c *= 1.15f;
      row[i] = Mix(c, haze, 0.35f);
    }
  }
  cv::Mat1f lum(g.height, g.width, 0.0f);
  AddValueNoise(g, d.seed ^ 0x301, 8.0, 8.0, 6.0f, &lum);
  AddValueNoise(g, d.seed ^ 0x302, 2.0, 2.0, 5.0f, &lum);
  AddValueNoise(g, d.seed ^ 0x303, 0.5, 0.5, 5.0f, &lum);
  AddWhiteNoise(g, d.seed ^ 0x304, d.texel_m, 4.0f, &lum);
  for (int j = 0; j < g.height; ++j) {
    Vec3f* row = img->ptr<Vec3f>(j);
    const float* n = lum.ptr<float>(j);
    for (int i = 0; i < g.width; ++i) row[i] = (row[i] + Vec3f(n[i], n[i], n[i])) * d.gain;
  }
}

// ---------------------------------------------------------------- trees

void LeavesTexture(const TextureDesc& d, const SampleGrid& g, cv::Mat3f* img) {
  const uint64_t s = d.seed;
  const Vec3f green(38 + 25 * HashUnit(Mix64(s ^ 1)), 100 + 45 * HashUnit(Mix64(s ^ 2)),
                    50 + 35 * HashUnit(Mix64(s ^ 3)));
  cv::Mat1f a(g.height, g.width, 0.0f), spots(g.height, g.width, 0.0f);
  AddValueNoise(g, s ^ 0x401, 0.05, 0.05, 0.3f, &a);
  AddValueNoise(g, s ^ 0x402, 0.015, 0.015, 0.25f, &a);
  AddWhiteNoise(g, s ^ 0x403, d.texel_m, 0.12f, &a);
  AddValueNoise(g, s ^ 0x404, 0.035, 0.035, 1.0f, &spots);
  for (int j = 0; j < g.height; ++j) {
    Vec3f* row = img->ptr<Vec3f>(j);
    for (int i = 0; i < g.width; ++i) {
      Vec3f c = green * (1.0f + a(j, i));
      const float sp = spots(j, i);
      if (sp > 0.45f) c *= 1.0f - 0.55f * Clamp01((sp - 0.45f) / 0.2f);
      if (sp < -0.6f) c = Mix(c, Vec3f(60, 170, 150), 0.5f * Clamp01((-0.6f - sp) / 0.2f));
      row[i] = c * d.gain;
    }
  }
}

void BarkTexture(const TextureDesc& d, const SampleGrid& g, cv::Mat3f* img) {
  const Vec3f bark(45, 62, 80);
  cv::Mat1f a(g.height, g.width, 0.0f), furrow(g.height, g.width, 0.0f);
  AddValueNoise(g, d.seed ^ 0x501, 0.03, 0.25, 0.3f, &a);
  AddValueNoise(g, d.seed ^ 0x502, 0.1, 0.6, 0.2f, &a);
  AddWhiteNoise(g, d.seed ^ 0x503, d.texel_m, 0.1f, &a);
  AddValueNoise(g, d.seed ^ 0x504, 0.02, 0.4, 1.0f, &furrow);
  for (int j = 0; j < g.height; ++j) {
    Vec3f* row = img->ptr<Vec3f>(j);
    for (int i = 0; i < g.width; ++i) {
      Vec3f c = bark * (1.0f + a(j, i));
      if (furrow(j, i) < -0.4f) c *= 1.0f - 0.5f * Clamp01((-0.4f - furrow(j, i)) / 0.2f);
      row[i] = c * d.gain;
    }
  }
}

// A guard rail's beam: u along the rail, v down from its top edge (0.3 m):
// two crests and a groove, bolts every 2 m, joints every 4 m, dirt and rust.
void MetalTexture(const TextureDesc& d, const SampleGrid& g, cv::Mat3f* img) {
  cv::Mat1f dirt(g.height, g.width, 0.0f);
  AddValueNoise(g, d.seed ^ 0x601, 0.6, 0.1, 0.15f, &dirt);
  AddValueNoise(g, d.seed ^ 0x602, 0.08, 0.04, 0.12f, &dirt);
  AddWhiteNoise(g, d.seed ^ 0x603, d.texel_m, 0.05f, &dirt);
  const Vec3f base(d.base_bgr), rust(40, 70, 120), dark = base * 0.35f;
  const double st = g.step_m;
  for (int j = 0; j < g.height; ++j) {
    const double v = g.v0_m + j * st;
    const float shade = static_cast<float>(1.0 + 0.22 * std::cos(2.0 * M_PI * v / 0.15));
    Vec3f* row = img->ptr<Vec3f>(j);
    for (int i = 0; i < g.width; ++i) {
      const double u = g.u0_m + i * st;
      Vec3f c = base * shade * (1.0f + dirt(j, i));
      if (dirt(j, i) > 0.17f) c = Mix(c, rust, Clamp01((dirt(j, i) - 0.17f) / 0.1f));
      const double joint = StripeCoverage(u, 4.0, 0.02, st);
      const double bolt =
          StripeCoverage(u + 0.02, 2.0, 0.04, st) * IntervalCoverage(v, 0.13, 0.17, st);
      c = Mix(c, dark, static_cast<float>(std::max(joint, bolt)));
      row[i] = c * d.gain;
    }
  }
}

// A painted surface: base colour with grain and dirt; style 1 (a car's side)
// adds a dark window band from 0.05 to 0.5 m below the top.
void PaintTexture(const TextureDesc& d, const SampleGrid& g, cv::Mat3f* img) {
  cv::Mat1f a(g.height, g.width, 0.0f);
  AddValueNoise(g, d.seed ^ 0x701, 0.5, 0.5, 0.08f, &a);
  AddValueNoise(g, d.seed ^ 0x702, 0.05, 0.05, 0.06f, &a);
  AddWhiteNoise(g, d.seed ^ 0x703, d.texel_m, 0.04f, &a);
  const Vec3f base(d.base_bgr), glass(45, 40, 38);
  for (int j = 0; j < g.height; ++j) {
    const double v = g.v0_m + j * g.step_m;
    const float band =
        d.style == 1 ? static_cast<float>(IntervalCoverage(v, 0.05, 0.5, g.step_m)) : 0.0f;
    Vec3f* row = img->ptr<Vec3f>(j);
    for (int i = 0; i < g.width; ++i) {
      row[i] = Mix(base, glass, band) * (1.0f + a(j, i)) * d.gain;
    }
  }
}

void CheckerTexture(const TextureDesc& d, const SampleGrid& g, cv::Mat3f* img) {
  const Vec3f dark(d.checker_dark), light(d.checker_light);
  for (int j = 0; j < g.height; ++j) {
    const double cy = StripeCoverage(g.v0_m + j * g.step_m, 2 * d.checker_m, d.checker_m, g.step_m);
    Vec3f* row = img->ptr<Vec3f>(j);
    for (int i = 0; i < g.width; ++i) {
      const double cx =
          StripeCoverage(g.u0_m + i * g.step_m, 2 * d.checker_m, d.checker_m, g.step_m);
      const double dark_frac = cx * cy + (1.0 - cx) * (1.0 - cy);
      row[i] = Mix(light, dark, static_cast<float>(dark_frac)) * d.gain;
    }
  }
}

}  // namespace

cv::Mat GenerateTexture(const Scene& scene, int texture, const SampleGrid& grid) {
  const TextureDesc& d = scene.textures[texture];
  cv::Mat3f img(grid.height, grid.width, Vec3f(0, 0, 0));
  switch (d.kind) {
    case TextureKind::kRoad:
      RoadTexture(scene, d, grid, &img);
      break;
    case TextureKind::kFacade:
      FacadeTexture(scene, d, grid, &img);
      break;
    case TextureKind::kBackground:
      BackgroundTexture(scene, d, grid, &img);
      break;
    case TextureKind::kLeaves:
      LeavesTexture(d, grid, &img);
      break;
    case TextureKind::kBark:
      BarkTexture(d, grid, &img);
      break;
    case TextureKind::kChecker:
      CheckerTexture(d, grid, &img);
      break;
    case TextureKind::kMetal:
      MetalTexture(d, grid, &img);
      break;
    case TextureKind::kPaint:
      PaintTexture(d, grid, &img);
      break;
  }
  const Lighting& light = scene.lighting;
  if (light.exposure != 1.0f || light.tint != cv::Vec3f(1.0f, 1.0f, 1.0f)) {
    const cv::Vec3f k = light.tint * light.exposure;
    img = img.mul(cv::Mat3f(img.size(), k));
  }
  cv::Mat out;
  img.convertTo(out, CV_8UC3);  // rounds and saturates
  return out;
}

}  // namespace slapse
