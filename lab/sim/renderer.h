// Renders a Scene from a camera pose: an anti-aliased 8-bit BGR image, the
// label each pixel sees, and per-16x16-macroblock labels (ground_truth.h).
//
// Method: each surface is cut into texture tiles; every tile piece is clipped
// against the near plane and the image, projected, and scan-converted at
// `supersampling` x the output resolution, front to back. Coverage and depth
// are resolved per sample: the inverse depth (affine in pixel coordinates for
// a plane) is z-tested per sample. The texture is sampled once per output
// pixel and piece (multisample anti-aliasing), at the centroid of the samples
// the piece wins, through the exact plane-induced homography, from the mip
// level that matches an output pixel's texel footprint (bilinear, blended
// between two levels near the middle between them). Pixels no surface covers
// show the sky (a gradient by elevation). The supersampled image is
// box-averaged (INTER_AREA) to the output size, which anti-aliases edges.
//
// Geometry follows core/common/camera.h exactly: pixel centres at integer
// coordinates. Supersample (i, j) has its centre at output coordinates
// ((i + 0.5) / s - 0.5, (j + 0.5) / s - 0.5), so the box average of the s x s
// samples of output pixel (x, y) is centred on (x, y).
//
// Macroblock labels count every supersample of the block: a plane id if at
// least kMbLabelCoverage of them see that plane, else kMbSky / kMbClutter if
// sky / clutter reach that coverage, else kMbMixed. Blocks at the right and
// bottom edges of sizes that are not multiples of 16 count their in-image part.
//
// Textures are made lazily, tile by tile, from the coarsest mip level down to
// the finest one a frame needs (finer levels are added when the camera comes
// closer), and dropped after `cache_frames` renders without use. Every level
// is generated directly by the band-limited texture procedures rather than by
// pyrDown from a finer one, so a level's content never depends on which
// levels exist: the image depends only on the scene, intrinsics, options and
// pose, not on what was rendered before. A Renderer is not thread-safe; it
// uses OpenCV's parallel_for_ internally.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <memory>
#include <unordered_map>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/camera.h"
#include "core/common/rigid3.h"
#include "core/common/status.h"
#include "lab/sim/scene.h"

namespace slapse {

struct RenderOptions {
  int supersampling = 2;  // samples per output pixel along each axis (1..4)
  double near_m = 0.05;   // near clipping distance in front of the camera
  int cache_frames = 45;  // drop texture tiles unused for this many renders
  cv::Vec3b sky_horizon_bgr{232, 222, 212};
  cv::Vec3b sky_zenith_bgr{205, 150, 100};
};

struct RenderedFrame {
  cv::Mat bgr;     // CV_8UC3, output size
  cv::Mat labels;  // CV_32S, output size: the label most of the pixel's samples see
  int mb_cols = 0, mb_rows = 0;
  std::vector<int> mb_labels;                           // row-major, mb_cols * mb_rows
  std::map<int, std::vector<MbShare>> mb_mixed_shares;  // mixed blocks: what they see
};

struct RenderStats {
  int64_t frames = 0;
  int64_t tiles_made = 0;  // texture tiles generated (including remakes)
  double texture_s = 0.0;  // time spent making textures
  double draw_s = 0.0;     // time spent projecting, rasterising, resolving
  size_t cached_tiles = 0;
};

class Renderer {
 public:
  // `scene` must outlive the renderer.
  static StatusOr<std::unique_ptr<Renderer>> Create(const Scene& scene,
                                                    const Intrinsics& intrinsics,
                                                    const RenderOptions& options = {});
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  Status Render(const Rigid3d& world_from_cam, RenderedFrame* frame);

  const RenderStats& stats() const { return stats_; }
  const Intrinsics& intrinsics() const { return intrinsics_; }

 private:
  struct Piece;
  struct Tile;
  struct Visible;
  struct View;
  struct RowScratch;
  Renderer(const Scene& scene, const Intrinsics& intrinsics, const RenderOptions& options);
  void BuildPieces();
  void MakeTiles(const std::vector<std::pair<uint64_t, int>>& requests);
  void MakeMissingTiles(const std::unordered_map<uint64_t, int>& requests);
  void EvictTiles();
  // Render's steps: the frame's camera, the pieces it sees (front to back),
  // rasterising them and the sky into the supersampled buffers.
  View MakeView(const Rigid3d& world_from_cam) const;
  std::vector<Eigen::Vector2d> ClipToImage(const Piece& piece, const View& v) const;
  std::optional<Visible> ProjectPiece(const Piece& piece, const View& v) const;
  std::vector<Visible> FindVisible(const View& v,
                                   std::unordered_map<uint64_t, int>* requests) const;
  void Rasterise(const View& v, const std::vector<Visible>& visible);
  static void CoverRow(const Visible& vis, const View& v, int row, RowScratch* s);
  void DrawRow(const Visible& vis, const View& v, int row, RowScratch* s);
  static void SampleTile(const Tile& tile, float j, float k, float lod, float c[3]);
  void PaintSky(const View& v, int y0, int y1);

  const Scene& scene_;
  Intrinsics intrinsics_;
  RenderOptions options_;
  std::vector<Piece> pieces_;
  std::unordered_map<uint64_t, std::shared_ptr<Tile>> tiles_;
  RenderStats stats_;
  // Supersampled buffers, reused across frames.
  cv::Mat color_;
  cv::Mat1f inv_depth_;
  cv::Mat1i sample_labels_;
};

// Renders one frame with a fresh renderer (tests, tools).
StatusOr<RenderedFrame> RenderFrame(const Scene& scene, const Intrinsics& intrinsics,
                                    const Rigid3d& world_from_cam,
                                    const RenderOptions& options = {});

// Macroblock labels from a per-sample label image (CV_32S, `supersampling`
// times the output size), by the rule above; with `mixed_shares`, also the
// labels each mixed block's samples see and their shares, largest first.
std::vector<int> MacroblockLabels(const cv::Mat& sample_labels, int supersampling, int* mb_cols,
                                  int* mb_rows,
                                  std::map<int, std::vector<MbShare>>* mixed_shares = nullptr);

}  // namespace slapse
