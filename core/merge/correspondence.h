// Correspondences between two consecutive anchor frames, built by merging the
// motion vectors of a GOP segment (paper Sec. V-A, V-B; docs/METHOD.md "MV merging").
//
// Frames: anchors k ("earlier") and k+1 ("later") in display order. Each
// correspondence belongs to one 16x16 macroblock cell of the later anchor:
// x_later_px is that cell's centre x^c_{k+1}, x_earlier_px = x^c_{k+1} + m the
// point it came from in the earlier anchor (m the merged MV).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace slapse {

// Segment types by the anchors' picture types (paper Sec. V-A).
enum class SegmentType { kIP, kPP, kPI, kII };
const char* SegmentTypeName(SegmentType type);

struct Correspondence {
  Eigen::Vector2d x_later_px = Eigen::Vector2d::Zero();    // MB centre in anchor k+1
  Eigen::Vector2d x_earlier_px = Eigen::Vector2d::Zero();  // matching point in anchor k
  // Per-axis variance of the merged MV given the number of in-line MVs merged
  // (isotropic: covariance = variance_px2 * I). Lemma 2, docs/METHOD.md "MV merging".
  double variance_px2 = 0.0;
  int mb_index = -1;   // row-major macroblock index in the later anchor
  int n_direct = 0;    // direct MVs merged (0 or 1)
  int n_indirect = 0;  // indirect MVs (through B frames) merged
};

struct AnchorPair {
  int64_t earlier_index = -1;  // display index of anchor k
  int64_t later_index = -1;    // display index of anchor k+1
  double earlier_timestamp_s = 0.0, later_timestamp_s = 0.0;
  SegmentType type = SegmentType::kPP;
  int n_b = 0;  // B frames between the anchors
  int mb_cols = 0, mb_rows = 0;
  std::vector<Correspondence> correspondences;
};

}  // namespace slapse
