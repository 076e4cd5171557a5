#include "lab/sim/renderer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string>

#include <Eigen/LU>
#include <opencv2/imgproc.hpp>

#include "core/common/mb_grid.h"
#include "core/common/timing.h"
#include "lab/sim/texture.h"

namespace slapse {

namespace {

// Texels of margin around each tile, so bilinear samples at a tile's edge see
// the neighbouring texture rather than a clamped border.
constexpr int kApron = 8;
constexpr int kMaxLevels = 10;
constexpr float kLevelScale[kMaxLevels] = {
    1.0f, 0.5f, 0.25f, 0.125f, 0.0625f, 0.03125f, 0.015625f, 0.0078125f, 0.00390625f, 0.001953125f};

using Clock = std::chrono::steady_clock;

// Keeps the part of a convex polygon where dot(n, p) + c >= 0.
template <typename V, typename F>
std::vector<V> ClipPolygon(const std::vector<V>& in, F signed_dist) {
  std::vector<V> out;
  out.reserve(in.size() + 2);
  const size_t n = in.size();
  for (size_t k = 0; k < n; ++k) {
    const V& a = in[k];
    const V& b = in[(k + 1) % n];
    const double da = signed_dist(a), db = signed_dist(b);
    if (da >= 0) out.push_back(a);
    if ((da >= 0) != (db >= 0)) {
      const double t = da / (da - db);
      out.push_back(a + t * (b - a));
    }
  }
  return out;
}

double PolygonArea2(const std::vector<Eigen::Vector2d>& p) {
  double a = 0.0;
  for (size_t k = 0; k < p.size(); ++k) {
    const auto& u = p[k];
    const auto& v = p[(k + 1) % p.size()];
    a += u.x() * v.y() - u.y() * v.x();
  }
  return 0.5 * std::abs(a);
}

// Side lengths of the mip levels of a tile image of n0 x n0 texels (pyrDown sizes).
int LevelSize(int n0, int level) {
  int n = n0;
  for (int m = 0; m < level; ++m) n = (n + 1) / 2;
  return n;
}
int CoarsestLevel(int n0) {
  int m = 0;
  while (m + 1 < kMaxLevels && LevelSize(n0, m + 1) >= 4) ++m;
  return m;
}

uint64_t TileKey(int texture, int ti, int tj) {
  return (static_cast<uint64_t>(texture) << 40) |
         (static_cast<uint64_t>(ti + (1 << 19)) & 0xFFFFF) << 20 |
         (static_cast<uint64_t>(tj + (1 << 19)) & 0xFFFFF);
}

// log2 to within ~0.005 (enough to pick and blend mip levels), without libm.
inline float FastLog2(float x) {
  uint32_t bits;
  std::memcpy(&bits, &x, sizeof(bits));
  const float e = static_cast<float>(static_cast<int>((bits >> 23) & 255) - 127);
  bits = (bits & 0x007FFFFFu) | 0x3F800000u;
  float m;
  std::memcpy(&m, &bits, sizeof(m));  // mantissa in [1, 2)
  return e + (-0.34484843f * m + 2.02466578f) * m - 1.67487759f;
}

// Bilinear sample of an 8-bit BGR image at (x, y) (texel centres at integers),
// clamped at the borders; adds weight * colour to acc.
inline void BilinearAdd(const cv::Mat& img, float x, float y, float weight, float* acc) {
  const int w = img.cols, h = img.rows;
  // floor() without a libm call (after clamping far outside values).
  x = std::min(std::max(x, -8.0f), w + 8.0f);
  y = std::min(std::max(y, -8.0f), h + 8.0f);
  int x0 = static_cast<int>(x + 4096.0f) - 4096, y0 = static_cast<int>(y + 4096.0f) - 4096;
  float fx = x - x0, fy = y - y0;
  int x1 = x0 + 1, y1 = y0 + 1;
  if (x0 < 0 || y0 < 0 || x1 >= w || y1 >= h) {
    if (x0 < 0) x0 = x1 = 0, fx = 0.0f;
    if (x1 >= w) x0 = x1 = w - 1, fx = 0.0f;
    if (y0 < 0) y0 = y1 = 0, fy = 0.0f;
    if (y1 >= h) y0 = y1 = h - 1, fy = 0.0f;
  }
  const uint8_t* r0 = img.ptr<uint8_t>(y0);
  const uint8_t* r1 = img.ptr<uint8_t>(y1);
  const uint8_t* a = r0 + 3 * x0;
  const uint8_t* b = r0 + 3 * x1;
  const uint8_t* c = r1 + 3 * x0;
  const uint8_t* d = r1 + 3 * x1;
  const float w11 = fx * fy, w10 = fx - w11, w01 = fy - w11, w00 = 1.0f - fx - w01;
  for (int ch = 0; ch < 3; ++ch) {
    acc[ch] += weight * (w00 * a[ch] + w10 * b[ch] + w01 * c[ch] + w11 * d[ch]);
  }
}

}  // namespace

struct Renderer::Piece {
  int label = kMbClutter;
  int texture = -1;
  int ti = 0, tj = 0;
  uint64_t key = 0;
  std::vector<Eigen::Vector3d> poly_world;  // convex
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double radius = 0.0;
  // Plane-local frame of the level-0 tile image: world point of tile image
  // texel (j, k) (its centre) is origin + j * du + k * dv.
  Eigen::Vector3d origin, du, dv;
};

struct Renderer::Tile {
  int finest = kMaxLevels;  // finest level present; all coarser ones exist
  int coarsest = 0;
  std::vector<cv::Mat> levels;  // index = level
  int64_t last_used = 0;
};

struct Renderer::Visible {
  const Piece* piece = nullptr;
  const Tile* tile = nullptr;
  std::vector<Eigen::Vector2d> poly;  // supersampled pixel coordinates, inside the image
  double q[9];                        // pixel -> (j, k, 1) / z in level-0 tile image texels
  float lod_c0 = 0.0f;                // 0.5 * log2 |det Q|
  double max_iz = 0.0;                // inverse depth of the nearest visible point
  int need_level = 0;
  int y0 = 0, y1 = -1;
};

Renderer::Renderer(const Scene& scene, const Intrinsics& intrinsics, const RenderOptions& options)
    : scene_(scene), intrinsics_(intrinsics), options_(options) {}

Renderer::~Renderer() = default;

StatusOr<std::unique_ptr<Renderer>> Renderer::Create(const Scene& scene,
                                                     const Intrinsics& intrinsics,
                                                     const RenderOptions& options) {
  if (intrinsics.width_px <= 0 || intrinsics.height_px <= 0 || intrinsics.fx_px <= 0 ||
      intrinsics.fy_px <= 0 || intrinsics.width_px > 8192 || intrinsics.height_px > 8192) {
    return InvalidArgumentError("renderer needs positive intrinsics and a size up to 8192");
  }
  if (options.supersampling < 1 || options.supersampling > 4) {
    return InvalidArgumentError("supersampling must be in 1..4, got " +
                                std::to_string(options.supersampling));
  }
  if (!(options.near_m > 0)) return InvalidArgumentError("near_m must be positive");
  for (const Surface& s : scene.surfaces) {
    if (s.texture < 0 || s.texture >= static_cast<int>(scene.textures.size())) {
      return InvalidArgumentError("surface refers to a missing texture");
    }
    const TextureDesc& d = scene.textures[s.texture];
    if (!(d.texel_m > 0) || d.tile_texels < 8 || d.tile_texels > 4096) {
      return InvalidArgumentError("texture needs texel_m > 0 and tile_texels in 8..4096");
    }
    if (s.label < 0 && s.label != kMbClutter) {
      return InvalidArgumentError("surface label must be a plane id or kMbClutter");
    }
    if (s.label >= static_cast<int>(scene.planes.size())) {
      return InvalidArgumentError("surface label refers to a missing plane");
    }
  }
  std::unique_ptr<Renderer> r(new Renderer(scene, intrinsics, options));
  r->BuildPieces();
  return r;
}

void Renderer::BuildPieces() {
  for (size_t si = 0; si < scene_.surfaces.size(); ++si) {
    const Surface& s = scene_.surfaces[si];
    const TextureDesc& d = scene_.textures[s.texture];
    const double tile_m = d.tile_texels * d.texel_m;
    const Eigen::Vector3d& o = s.origin_world;
    const Eigen::Vector3d& u = s.u_axis_world;
    const Eigen::Vector3d& v = s.v_axis_world;
    for (const auto& poly : s.polygons_world) {
      if (poly.size() < 3) continue;
      std::vector<Eigen::Vector2d> uv;
      Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
      for (const auto& p : poly) {
        uv.emplace_back((p - o).dot(u), (p - o).dot(v));
        lo = lo.cwiseMin(uv.back());
        hi = hi.cwiseMax(uv.back());
      }
      const int i0 = static_cast<int>(std::floor(lo.x() / tile_m));
      const int i1 = static_cast<int>(std::floor(hi.x() / tile_m));
      const int j0 = static_cast<int>(std::floor(lo.y() / tile_m));
      const int j1 = static_cast<int>(std::floor(hi.y() / tile_m));
      for (int tj = j0; tj <= j1; ++tj) {
        for (int ti = i0; ti <= i1; ++ti) {
          const double ua = ti * tile_m, ub = (ti + 1) * tile_m;
          const double va = tj * tile_m, vb = (tj + 1) * tile_m;
          std::vector<Eigen::Vector2d> c = uv;
          c = ClipPolygon(c, [&](const Eigen::Vector2d& p) { return p.x() - ua; });
          c = ClipPolygon(c, [&](const Eigen::Vector2d& p) { return ub - p.x(); });
          c = ClipPolygon(c, [&](const Eigen::Vector2d& p) { return p.y() - va; });
          c = ClipPolygon(c, [&](const Eigen::Vector2d& p) { return vb - p.y(); });
          if (c.size() < 3 || PolygonArea2(c) < 1e-8) continue;
          Piece piece;
          piece.label = s.label;
          piece.texture = s.texture;
          piece.ti = ti;
          piece.tj = tj;
          piece.key = TileKey(s.texture, ti, tj);
          for (const auto& p : c) piece.poly_world.push_back(o + p.x() * u + p.y() * v);
          for (const auto& p : piece.poly_world) piece.centre += p;
          piece.centre /= static_cast<double>(piece.poly_world.size());
          for (const auto& p : piece.poly_world) {
            piece.radius = std::max(piece.radius, (p - piece.centre).norm());
          }
          // Level-0 tile image texel j has its centre at u = (ti*T - apron + j + 0.5) * texel.
          const double a0 = ti * d.tile_texels - kApron + 0.5;
          const double b0 = tj * d.tile_texels - kApron + 0.5;
          piece.du = d.texel_m * u;
          piece.dv = d.texel_m * v;
          piece.origin = o + a0 * piece.du + b0 * piece.dv;
          pieces_.push_back(std::move(piece));
        }
      }
    }
  }
}

void Renderer::MakeTiles(const std::vector<std::pair<uint64_t, int>>& requests) {
  // Each request: (key, finest level needed). Levels are generated directly
  // (box-filtered procedurally), so a level's content never depends on which
  // other levels exist: rendering does not depend on the history of poses.
  struct Job {
    uint64_t key;
    int texture, ti, tj, level;
    std::shared_ptr<Tile> tile;
  };
  std::vector<Job> jobs;
  for (const auto& [key, level] : requests) {
    auto it = tiles_.find(key);
    std::shared_ptr<Tile> tile;
    if (it == tiles_.end()) {
      tile = std::make_shared<Tile>();
      const int texture = static_cast<int>(key >> 40);
      const int n0 = scene_.textures[texture].tile_texels + 2 * kApron;
      tile->coarsest = CoarsestLevel(n0);
      tile->levels.resize(tile->coarsest + 1);
      tiles_.emplace(key, tile);
    } else {
      tile = it->second;
    }
    const int want = std::min(level, tile->coarsest);
    const int from = std::min(tile->finest, tile->coarsest + 1);
    for (int m = want; m < from; ++m) {
      jobs.push_back({key, static_cast<int>(key >> 40),
                      static_cast<int>((key >> 20) & 0xFFFFF) - (1 << 19),
                      static_cast<int>(key & 0xFFFFF) - (1 << 19), m, tile});
    }
  }
  if (jobs.empty()) return;
  cv::parallel_for_(cv::Range(0, static_cast<int>(jobs.size())), [&](const cv::Range& range) {
    for (int k = range.start; k < range.end; ++k) {
      Job& job = jobs[k];
      const TextureDesc& d = scene_.textures[job.texture];
      const int n0 = d.tile_texels + 2 * kApron;
      SampleGrid grid;
      grid.step_m = d.texel_m * std::ldexp(1.0, job.level);
      grid.u0_m = (job.ti * d.tile_texels - kApron + 0.5) * d.texel_m;
      grid.v0_m = (job.tj * d.tile_texels - kApron + 0.5) * d.texel_m;
      grid.width = grid.height = LevelSize(n0, job.level);
      job.tile->levels[job.level] = GenerateTexture(scene_, job.texture, grid);
    }
  });
  for (const Job& job : jobs) job.tile->finest = std::min(job.tile->finest, job.level);
  stats_.tiles_made += static_cast<int64_t>(jobs.size());
}

// The supersampled camera of one frame: sample i is centred at output
// x = (i + 0.5) / ss - 0.5, so the sample intrinsics are K scaled by ss with
// the principal point moved by 0.5 (ss - 1).
struct Renderer::View {
  int ss = 1, W = 0, H = 0, ws = 0, hs = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Eigen::Matrix3d k_inv;
  Eigen::Matrix3d R;  // cam_from_world
  Eigen::Vector3d t;
  Eigen::Matrix3d r_wc;  // world_from_cam
  float lod_pixel = 0;   // log2 ss: an output pixel's footprint in samples
  // Frustum side planes through the camera centre (inside: n . X >= 0).
  Eigen::Vector3d side[4];
};

// Per-thread scratch of the rasteriser: one output row of `ss` sample rows.
struct Renderer::RowScratch {
  int span0[4], span1[4];  // covered samples of each sample row
  int px0 = 0, px1 = -1;   // output pixels any of them touch
  int hit_x[16], hit_y[16];
  float hit_z[16];
  std::vector<float> iz_rows[4];
  std::vector<uint8_t> won_rows[4];
};

Renderer::View Renderer::MakeView(const Rigid3d& world_from_cam) const {
  View v;
  v.ss = options_.supersampling;
  v.W = intrinsics_.width_px;
  v.H = intrinsics_.height_px;
  v.ws = v.W * v.ss;
  v.hs = v.H * v.ss;
  v.fx = intrinsics_.fx_px * v.ss;
  v.fy = intrinsics_.fy_px * v.ss;
  v.cx = intrinsics_.cx_px * v.ss + 0.5 * (v.ss - 1);
  v.cy = intrinsics_.cy_px * v.ss + 0.5 * (v.ss - 1);
  v.k_inv << 1.0 / v.fx, 0, -v.cx / v.fx, 0, 1.0 / v.fy, -v.cy / v.fy, 0, 0, 1;
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  v.R = cam_from_world.R();
  v.t = cam_from_world.translation;
  v.r_wc = world_from_cam.R();
  v.lod_pixel = static_cast<float>(std::log2(static_cast<double>(v.ss)));
  v.side[0] = {v.fx, 0, v.cx + 0.5};
  v.side[1] = {-v.fx, 0, v.ws - 0.5 - v.cx};
  v.side[2] = {0, v.fy, v.cy + 0.5};
  v.side[3] = {0, -v.fy, v.hs - 0.5 - v.cy};
  for (auto& n : v.side) n.normalize();
  return v;
}

// A piece's polygon in supersampled pixels, clipped to the near plane and the
// image; fewer than 3 vertices when it is not visible.
std::vector<Eigen::Vector2d> Renderer::ClipToImage(const Piece& piece, const View& v) const {
  const double near = options_.near_m;
  const Eigen::Vector3d c = v.R * piece.centre + v.t;
  if (c.z() + piece.radius < near) return {};
  bool outside = false;
  for (const auto& n : v.side) outside = outside || n.dot(c) < -piece.radius;
  if (outside) return {};
  std::vector<Eigen::Vector3d> cam;
  cam.reserve(piece.poly_world.size());
  for (const auto& p : piece.poly_world) cam.push_back(v.R * p + v.t);
  cam = ClipPolygon(cam, [&](const Eigen::Vector3d& p) { return p.z() - near; });
  if (cam.size() < 3) return {};
  std::vector<Eigen::Vector2d> px;
  px.reserve(cam.size());
  for (const auto& p : cam) {
    px.emplace_back(v.fx * p.x() / p.z() + v.cx, v.fy * p.y() / p.z() + v.cy);
  }
  const double ws = v.ws, hs = v.hs;
  px = ClipPolygon(px, [&](const Eigen::Vector2d& p) { return p.x() + 0.5; });
  px = ClipPolygon(px, [&](const Eigen::Vector2d& p) { return ws - 0.5 - p.x(); });
  px = ClipPolygon(px, [&](const Eigen::Vector2d& p) { return p.y() + 0.5; });
  px = ClipPolygon(px, [&](const Eigen::Vector2d& p) { return hs - 0.5 - p.y(); });
  return px;
}

std::optional<Renderer::Visible> Renderer::ProjectPiece(const Piece& piece, const View& v) const {
  std::vector<Eigen::Vector2d> px = ClipToImage(piece, v);
  if (px.size() < 3) return std::nullopt;
  // Camera point of tile texel (j, k): G (j, k, 1); a pixel p sees
  // (j, k, 1) / z = G^-1 K^-1 p, so the third row of Q is the inverse depth.
  Eigen::Matrix3d g;
  g.col(0) = v.R * piece.du;
  g.col(1) = v.R * piece.dv;
  g.col(2) = v.R * piece.origin + v.t;
  const double det_g = g.determinant();
  if (!std::isfinite(det_g) || std::abs(det_g) < 1e-18) return std::nullopt;  // edge-on
  const Eigen::Matrix3d q = g.inverse() * v.k_inv;
  Visible vis;
  vis.piece = &piece;
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) vis.q[3 * r + col] = q(r, col);
  }
  const double det_q = q.determinant();
  vis.lod_c0 = static_cast<float>(0.5 * std::log2(std::abs(det_q)));
  // Finest level needed: the largest inverse depth is at a vertex (affine).
  double max_iz = 0.0;
  double ymin = 1e300, ymax = -1e300;
  for (const auto& p : px) {
    max_iz = std::max(max_iz, q(2, 0) * p.x() + q(2, 1) * p.y() + q(2, 2));
    ymin = std::min(ymin, p.y());
    ymax = std::max(ymax, p.y());
  }
  if (!(max_iz > 0)) return std::nullopt;
  const double min_lod = vis.lod_c0 + std::log2(static_cast<double>(options_.supersampling)) -
                         1.5 * std::log2(max_iz);
  vis.need_level = std::clamp(static_cast<int>(std::floor(min_lod)), 0, kMaxLevels - 1);
  vis.y0 = std::max(0, static_cast<int>(std::ceil(ymin)));
  vis.y1 = std::min(v.hs - 1, static_cast<int>(std::floor(ymax)));
  if (vis.y1 < vis.y0) return std::nullopt;
  vis.poly = std::move(px);
  vis.max_iz = max_iz;
  return vis;
}

std::vector<Renderer::Visible> Renderer::FindVisible(
    const View& v, std::unordered_map<uint64_t, int>* requests) const {
  std::vector<Visible> visible;
  for (const Piece& piece : pieces_) {
    std::optional<Visible> vis = ProjectPiece(piece, v);
    if (!vis.has_value()) continue;
    auto it = requests->find(piece.key);
    if (it == requests->end()) {
      requests->emplace(piece.key, vis->need_level);
    } else {
      it->second = std::min(it->second, vis->need_level);
    }
    visible.push_back(std::move(*vis));
  }
  // Front to back (nearest point first), so hidden samples fail the depth
  // test before texturing. The order is deterministic (ties by piece order).
  std::stable_sort(visible.begin(), visible.end(),
                   [](const Visible& a, const Visible& b) { return a.max_iz > b.max_iz; });
  return visible;
}

// Makes the tiles (and levels) the visible pieces need that the cache lacks, in parallel.
void Renderer::MakeMissingTiles(const std::unordered_map<uint64_t, int>& requests) {
  std::vector<std::pair<uint64_t, int>> todo;
  for (const auto& [key, level] : requests) {
    auto it = tiles_.find(key);
    if (it == tiles_.end() || it->second->finest > std::min(level, it->second->coarsest)) {
      todo.emplace_back(key, level);
    }
  }
  std::sort(todo.begin(), todo.end());
  MakeTiles(todo);
}

// Covered samples of each sample row of output row `row`: sample centres
// inside the polygon (scratch->span0/span1, and the output pixels px0..px1).
void Renderer::CoverRow(const Visible& vis, const View& v, int row, RowScratch* s) {
  const size_t nv = vis.poly.size();
  s->px0 = v.ws;
  s->px1 = -1;
  for (int r = 0; r < v.ss; ++r) {
    const int y = row * v.ss + r;
    s->span0[r] = 0;
    s->span1[r] = -1;
    if (y < vis.y0 || y > vis.y1) continue;
    double xl = 1e300, xr = -1e300;
    for (size_t e = 0; e < nv; ++e) {
      const Eigen::Vector2d& a = vis.poly[e];
      const Eigen::Vector2d& b = vis.poly[(e + 1) % nv];
      if ((a.y() <= y && b.y() >= y) || (b.y() <= y && a.y() >= y)) {
        if (a.y() == b.y()) {
          xl = std::min({xl, a.x(), b.x()});
          xr = std::max({xr, a.x(), b.x()});
        } else {
          const double x = a.x() + (y - a.y()) * (b.x() - a.x()) / (b.y() - a.y());
          xl = std::min(xl, x);
          xr = std::max(xr, x);
        }
      }
    }
    s->span0[r] = std::max(0, static_cast<int>(std::ceil(xl - 1e-7)));
    s->span1[r] = std::min(v.ws - 1, static_cast<int>(std::floor(xr + 1e-7)));
    if (s->span0[r] <= s->span1[r]) {
      s->px0 = std::min(s->px0, s->span0[r] / v.ss);
      s->px1 = std::max(s->px1, s->span1[r] / v.ss);
    }
  }
}

// The texture of `tile` at tile-image texel (j, k) with level of detail
// `lod`, BGR + 0.5 (the conversion to 8 bits truncates).
void Renderer::SampleTile(const Tile& tile, float j, float k, float lod, float c[3]) {
  lod = std::max(lod, static_cast<float>(tile.finest));
  int l0 = static_cast<int>(lod);
  // Blend two levels only around the middle between them
  // ("brilinear"): half the pixels need a single lookup.
  float f = std::min(std::max(2.0f * (lod - l0) - 0.5f, 0.0f), 1.0f);
  if (l0 >= tile.coarsest) {
    l0 = tile.coarsest;
    f = 0.0f;
  }
  c[0] = c[1] = c[2] = 0.5f;
  const float s0 = kLevelScale[l0];
  if (f < 1.0f) BilinearAdd(tile.levels[l0], j * s0, k * s0, 1.0f - f, c);
  if (f > 0.0f) BilinearAdd(tile.levels[l0 + 1], j * s0 * 0.5f, k * s0 * 0.5f, f, c);
}

void Renderer::DrawRow(const Visible& vis, const View& v, int row, RowScratch* s) {
  CoverRow(vis, v, row, s);
  const double* q = vis.q;
  const int ss = v.ss;
  // Depth test of each sample row's span in one tight loop.
  for (int r = 0; r < ss; ++r) {
    if (s->span0[r] > s->span1[r]) continue;
    const int y = row * ss + r;
    const float* zrow = inv_depth_.ptr<float>(y);
    const double wz = q[7] * y + q[8];
    float* izr = s->iz_rows[r].data();
    uint8_t* wr = s->won_rows[r].data();
    for (int x = s->span0[r]; x <= s->span1[r]; ++x) {
      const float izf = static_cast<float>(q[6] * x + wz);
      izr[x] = izf;
      wr[x] = izf > zrow[x];
    }
  }
  const Tile& tile = *vis.tile;
  for (int px = s->px0; px <= s->px1; ++px) {
    int n = 0;
    double sx = 0.0, sy = 0.0;
    for (int r = 0; r < ss; ++r) {
      const int y = row * ss + r;
      const int xa = std::max(s->span0[r], px * ss), xb = std::min(s->span1[r], px * ss + ss - 1);
      for (int x = xa; x <= xb; ++x) {
        if (!s->won_rows[r][x]) continue;
        s->hit_x[n] = x;
        s->hit_y[n] = y;
        s->hit_z[n] = s->iz_rows[r][x];
        ++n;
        sx += x;
        sy += y;
      }
    }
    if (n == 0) continue;
    // Texture at the centroid of the won samples (inside the polygon).
    const double cxs = sx / n, cys = sy / n;
    const double iz = q[6] * cxs + q[7] * cys + q[8];
    const double inv = 1.0 / iz;
    const float j = static_cast<float>((q[0] * cxs + q[1] * cys + q[2]) * inv);
    const float k = static_cast<float>((q[3] * cxs + q[4] * cys + q[5]) * inv);
    float c[3];
    SampleTile(tile, j, k, vis.lod_c0 + v.lod_pixel - 1.5f * FastLog2(static_cast<float>(iz)), c);
    const uint8_t b = static_cast<uint8_t>(std::min(255.0f, c[0]));
    const uint8_t g = static_cast<uint8_t>(std::min(255.0f, c[1]));
    const uint8_t rr = static_cast<uint8_t>(std::min(255.0f, c[2]));
    for (int m = 0; m < n; ++m) {
      uint8_t* out = color_.ptr<uint8_t>(s->hit_y[m]) + 3 * s->hit_x[m];
      out[0] = b;
      out[1] = g;
      out[2] = rr;
      inv_depth_(s->hit_y[m], s->hit_x[m]) = s->hit_z[m];
      sample_labels_(s->hit_y[m], s->hit_x[m]) = vis.piece->label;
    }
  }
}

// Sky where nothing was drawn in sample rows y0..y1: a gradient by the ray's elevation.
void Renderer::PaintSky(const View& v, int y0, int y1) {
  const cv::Vec3f horizon(options_.sky_horizon_bgr), zenith(options_.sky_zenith_bgr);
  for (int y = y0; y <= y1; ++y) {
    const int* lrow = sample_labels_.ptr<int>(y);
    uint8_t* crow = color_.ptr<uint8_t>(y);
    const double b = (y - v.cy) / v.fy;
    for (int x = 0; x < v.ws; ++x) {
      if (lrow[x] != kMbSky) continue;
      const double a = (x - v.cx) / v.fx;
      const double dz = v.r_wc(2, 0) * a + v.r_wc(2, 1) * b + v.r_wc(2, 2);
      const double elev = dz / std::sqrt(a * a + b * b + 1.0);
      const float w = static_cast<float>(std::clamp(1.8 * elev, 0.0, 1.0));
      const cv::Vec3f c = horizon + (zenith - horizon) * w;
      for (int ch = 0; ch < 3; ++ch) crow[3 * x + ch] = static_cast<uint8_t>(c[ch] + 0.5f);
    }
  }
}

// Rasterises in bands of output rows (one writer per pixel; the same piece
// order everywhere). Coverage and depth are resolved per sample; the texture
// is sampled once per output pixel and piece, at the centroid of the samples
// it wins (multisample anti-aliasing), with the footprint of an output pixel.
void Renderer::Rasterise(const View& v, const std::vector<Visible>& visible) {
  color_.create(v.hs, v.ws, CV_8UC3);
  inv_depth_.create(v.hs, v.ws);
  sample_labels_.create(v.hs, v.ws);
  color_.setTo(cv::Scalar::all(0));
  inv_depth_.setTo(0.0f);
  sample_labels_.setTo(static_cast<int>(kMbSky));
  const int band_rows = 8;  // output rows
  const int bands = (v.H + band_rows - 1) / band_rows;
  cv::parallel_for_(cv::Range(0, bands), [&](const cv::Range& range) {
    RowScratch scratch;
    for (int r = 0; r < v.ss; ++r) {
      scratch.iz_rows[r].resize(v.ws);
      scratch.won_rows[r].resize(v.ws);
    }
    for (int band = range.start; band < range.end; ++band) {
      const int row0 = band * band_rows, row1 = std::min(v.H, row0 + band_rows) - 1;
      const int yb0 = row0 * v.ss, yb1 = (row1 + 1) * v.ss - 1;
      for (const Visible& vis : visible) {
        if (vis.y1 < yb0 || vis.y0 > yb1) continue;
        const int r0 = std::max(row0, vis.y0 / v.ss), r1 = std::min(row1, vis.y1 / v.ss);
        for (int row = r0; row <= r1; ++row) DrawRow(vis, v, row, &scratch);
      }
      PaintSky(v, yb0, yb1);
    }
  });
}

namespace {

// Per output pixel, the label most of its samples see (ties: the first in
// row-major order).
void ResolveLabels(const cv::Mat1i& sample_labels, int ss, int W, int H, cv::Mat* labels) {
  labels->create(H, W, CV_32S);
  for (int y = 0; y < H; ++y) {
    int* out = labels->ptr<int>(y);
    for (int x = 0; x < W; ++x) {
      int vals[16] = {0};
      int n = 0;
      bool uniform = true;
      for (int dy = 0; dy < ss; ++dy) {
        const int* row = sample_labels.ptr<int>(y * ss + dy) + x * ss;
        for (int dx = 0; dx < ss; ++dx) {
          vals[n] = row[dx];
          uniform = uniform && vals[n] == vals[0];
          ++n;
        }
      }
      int best = vals[0];
      if (!uniform) {
        int best_n = 0;
        for (int a = 0; a < n; ++a) {
          int count = 0;
          for (int b = 0; b < n; ++b) count += vals[b] == vals[a];
          if (count > best_n) {
            best_n = count;
            best = vals[a];
          }
        }
      }
      out[x] = best;
    }
  }
}

}  // namespace

// Drops tiles nobody used for a while.
void Renderer::EvictTiles() {
  for (auto it = tiles_.begin(); it != tiles_.end();) {
    if (stats_.frames - it->second->last_used > options_.cache_frames) {
      it = tiles_.erase(it);
    } else {
      ++it;
    }
  }
  stats_.cached_tiles = tiles_.size();
}

Status Renderer::Render(const Rigid3d& world_from_cam, RenderedFrame* frame) {
  if (frame == nullptr) return InvalidArgumentError("Render: null frame");
  const auto t_start = Clock::now();
  const View v = MakeView(world_from_cam);
  std::unordered_map<uint64_t, int> requests;
  std::vector<Visible> visible = FindVisible(v, &requests);

  const auto t_tex = Clock::now();
  MakeMissingTiles(requests);
  const auto t_tex_done = Clock::now();
  stats_.texture_s += SecondsBetween(t_tex, t_tex_done);
  ++stats_.frames;
  for (Visible& vis : visible) {
    Tile* tile = tiles_.at(vis.piece->key).get();
    tile->last_used = stats_.frames;
    vis.tile = tile;
  }

  Rasterise(v, visible);
  // Resolve: box average to the output size, labels.
  if (v.ss == 1) {
    color_.copyTo(frame->bgr);
  } else {
    cv::resize(color_, frame->bgr, cv::Size(v.W, v.H), 0, 0, cv::INTER_AREA);
  }
  ResolveLabels(sample_labels_, v.ss, v.W, v.H, &frame->labels);
  frame->mb_labels = MacroblockLabels(sample_labels_, v.ss, &frame->mb_cols, &frame->mb_rows,
                                      &frame->mb_mixed_shares);
  EvictTiles();
  stats_.draw_s += SecondsBetween(t_start, Clock::now()) - SecondsBetween(t_tex, t_tex_done);
  return Status::Ok();
}

std::vector<int> MacroblockLabels(const cv::Mat& sample_labels, int supersampling, int* mb_cols,
                                  int* mb_rows, std::map<int, std::vector<MbShare>>* mixed_shares) {
  if (mixed_shares != nullptr) mixed_shares->clear();
  const int ss = supersampling;
  const int W = sample_labels.cols / ss, H = sample_labels.rows / ss;
  const int cols = MbCount(W), rows = MbCount(H);
  *mb_cols = cols;
  *mb_rows = rows;
  std::vector<int> labels(static_cast<size_t>(cols) * rows, kMbMixed);
  std::vector<std::pair<int, int>> counts;
  for (int by = 0; by < rows; ++by) {
    for (int bx = 0; bx < cols; ++bx) {
      counts.clear();
      const int y0 = by * kMbSizePx * ss, y1 = std::min(H, (by + 1) * kMbSizePx) * ss;
      const int x0 = bx * kMbSizePx * ss, x1 = std::min(W, (bx + 1) * kMbSizePx) * ss;
      int last = std::numeric_limits<int>::min();
      size_t last_idx = 0;
      for (int y = y0; y < y1; ++y) {
        const int* row = sample_labels.ptr<int>(y);
        for (int x = x0; x < x1; ++x) {
          const int l = row[x];
          if (l != last) {
            last_idx = counts.size();
            for (size_t k = 0; k < counts.size(); ++k) {
              if (counts[k].first == l) last_idx = k;
            }
            if (last_idx == counts.size()) counts.emplace_back(l, 0);
            last = l;
          }
          ++counts[last_idx].second;
        }
      }
      const int total = (y1 - y0) * (x1 - x0);
      const size_t mb = static_cast<size_t>(by) * cols + bx;
      for (const auto& [label, n] : counts) {
        if (static_cast<double>(n) >= kMbLabelCoverage * total) labels[mb] = label;
      }
      if (labels[mb] == kMbMixed && mixed_shares != nullptr) {
        std::sort(counts.begin(), counts.end(),
                  [](const auto& a, const auto& b) { return a.second > b.second; });
        std::vector<MbShare>& shares = (*mixed_shares)[static_cast<int>(mb)];
        for (const auto& [label, n] : counts) {
          shares.push_back({label, static_cast<float>(n) / total});
        }
      }
    }
  }
  return labels;
}

StatusOr<RenderedFrame> RenderFrame(const Scene& scene, const Intrinsics& intrinsics,
                                    const Rigid3d& world_from_cam, const RenderOptions& options) {
  auto renderer = Renderer::Create(scene, intrinsics, options);
  if (!renderer.ok()) return renderer.status();
  RenderedFrame frame;
  SLAPSE_RETURN_IF_ERROR((*renderer)->Render(world_from_cam, &frame));
  return frame;
}

}  // namespace slapse
