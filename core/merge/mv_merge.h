// MV merging across a GOP segment (paper Sec. V-A; docs/METHOD.md "MV merging").
//
// Between consecutive anchors k (earlier) and k+1 (later) a macroblock cell c
// of k+1 collects candidate correspondences:
//  - direct (IP, PP): the P frame k+1's vector of the block at c,
//    (c in k+1) <-> (c + m_d in k), error variance sigma^2 per axis;
//  - indirect, through each B frame b: a B block at y with a past vector f and
//    a future vector g gives (y + g in k+1) <-> (y + f in k), filed under the
//    cell containing y + g, error variance 2 sigma^2 on the displacement f - g.
// Outliers inside a cell's candidate set are gated by consensus: the candidate
// whose displacement agrees (within the gate) with the most weight seeds the
// in-line set; a cell whose candidates all disagree gives no correspondence
// (a lone candidate is kept: nothing contradicts it). The in-line MVs (IMVs)
// are merged with inverse-variance weights (2 for direct, 1 for indirect).
//
// Where this differs from the paper, and why:
//  - Weights 2:1 (inverse variances), not sqrt(2):1 (docs/METHOD.md "MV merging").
//  - Indirect candidates start at y + g, up to 8 px from the cell centre. The
//    paper files their displacement at the centre, which on a near road (flow
//    gradients of 0.2-0.5 px/px over a segment) costs pixels. We merge start
//    and end points instead: the merged correspondence is (weighted mean of
//    starts) <-> (weighted mean of ends), exact for locally affine motion.
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/merge/correspondence.h"
#include "core/mv/frame_record.h"

namespace slapse {

struct MergeOptions {
  // Two candidates agree when their displacements differ by at most
  // max(gate_sigmas * sigma of the difference, gate_min_px).
  double gate_sigmas = 4.0;
  double gate_min_px = 1.0;
  // The flow changes across a cell: two direct candidates at different
  // places in it (H.264's partitions of one macroblock) may differ by that
  // change. Their gate widens by gate_flow_gradient_per_px x the distance
  // between their later points (px) x the smaller displacement (px): the
  // flow's relative change per px. On a road plane the change is ~2 / (rows
  // below the horizon) per px, e.g. 0.02 / px 100 rows down; at 10 fps and
  // 70 km/h two 8x8 partitions 8 px apart there differ by 3-4 px, and with 0
  // (positions ignored) the cell was dropped. Indirect candidates get no
  // allowance: their later point y + g moves with a wrong g. 0.02 chosen on
  // the tuning drives (docs/TRAJECTORY.md "Session 25").
  double gate_flow_gradient_per_px = 0.02;
  // Texture gate: a cell whose block in the later anchor has a texture
  // (FrameRecord::mb_texture, the structure tensor's smaller eigenvalue,
  // (levels / px)^2) below this gives no correspondence: its content does not
  // pin the motion down (sky, blank walls, 1-D structure), so every vector
  // filed there, direct or indirect, is the encoder's guess. Anchors without
  // mb_texture are not gated; 0 = off. On the tuning drives' P frames, 98 %
  // of the vectors of blocks below 0.03 are in the sky, and those on planes
  // are within 2 px of the truth 26-65 % of the time against 72-97 % above
  // 0.1 (bench/mv_accuracy --texture; docs/METHOD.md "MV merging").
  double min_mb_texture = 0.03;
  bool use_direct = true;
  bool use_indirect = true;
  // IPPP streams (no B frames, one frame between anchors): P-frame vector
  // fields are chained (composed, interpolating the earlier field bilinearly
  // between macroblock cells) until the anchors are at least this many
  // seconds apart, one pair per chain: at the default 0.045 s, 2 frames at
  // 24-30 fps, 3 at 50-60 fps, 1 at 10-20 fps. Segments with B frames are
  // never chained, nor, once a B frame has been seen, the P-P segments of a
  // stream with adaptive B frames (x264's defaults: chaining them made one
  // of five reporting drives 0.05 -> 0.22 %, bench/codec_ate seed 7); 0 turns
  // chaining off (one pair, and a step, per P frame).
  // Chosen on the h264-ippp tuning drives (docs/TRAJECTORY.md "Session 29"):
  // ATE median / worst 0.13 / 1.83 % unchained, 0.09 / 0.95 % at 0.045 s
  // (0.025 s: 0.11 / 1.72; 0.06 s: 0.09 / 1.20; 0.07 s: 0.10 / 0.95); half
  // the pairs at 30 fps, the stages 13 % cheaper on a 30 fps camera stream
  // (each pair costs more, and the frame between is posed on its own;
  // docs/BENCHMARKS.md "Session 29").
  // The frames between a chain's anchors are posed with it
  // (core/pipeline/frame_poses.h). Earlier, before the window refiner and the
  // texture gate, one-frame pairs had measured better (docs/METHOD.md
  // "Beyond the paper").
  double min_pair_span_s = 0.045;
  // The longest chain, frames, whatever the timestamps (a 240 fps camera
  // reaches 0.045 s in 11 frames).
  static constexpr int kMaxChainFrames = 16;
  // Direct vectors of a P frame whose reference is not certain
  // (FrameRecord::reference_certain false: several references allowed):
  //  kKeep: used as if they referred to the previous anchor (mixes references);
  //  kDrop: not used (only certain references);
  //  kConsistent: kept where they agree with the frame's local field (the
  //    median of the vectors in the 3x3 macroblocks around them) within
  //    max(consistent_min_px, consistent_rel * |median|); a vector to an older
  //    reference is about 2-3 times as long as its neighbours' (constant
  //    motion) and fails (docs/METHOD.md "Reference handling").
  enum class UncertainRefs { kKeep, kDrop, kConsistent };
  UncertainRefs uncertain_refs = UncertainRefs::kConsistent;
  double consistent_min_px = 1.0;
  double consistent_rel = 0.33;
  // Under a B-pyramid (SegmentMerger::b_pyramid_seen) the B frames between
  // two anchors may refer to each other, and only the first-decoded one (the
  // pyramid's top, decoded right after the later anchor) refers to anchors
  // alone: its future vectors to the later anchor (no other future reference
  // exists when it is decoded), its past ones to the earlier anchor or, with
  // extra references, an older frame (handled as uncertain_refs says). True:
  // its bi-predicted blocks give indirect candidates; false: a B-pyramid's
  // pairs have the P frame's direct vectors only (docs/METHOD.md "Reference
  // handling").
  bool pyramid_top_b = true;
};

// One candidate correspondence of a cell.
struct MvCandidate {
  Eigen::Vector2d later_px;    // start point in anchor k+1
  Eigen::Vector2d earlier_px;  // end point in anchor k
  bool direct = false;         // direct (variance sigma^2) or indirect (2 sigma^2)
};

struct MergedMv {
  Eigen::Vector2d later_px, earlier_px;
  double variance_px2 = 0.0;  // per axis, given the merged counts
  int n_direct = 0, n_indirect = 0;
};

// The part of the consensus gate from the MV noise, px: two candidates agree
// within max(gate_sigmas * sigma of their difference, gate_min_px), a
// direct one having variance sigma_px^2 and an indirect one 2 sigma_px^2
// (MergeCell adds the flow's change between two direct ones).
double MergeNoiseGatePx(bool a_direct, bool b_direct, double sigma_px, const MergeOptions& options);

// Gates `candidates` by consensus and merges the in-line ones. Returns nothing
// when there are none or when no two of several candidates agree.
std::optional<MergedMv> MergeCell(const std::vector<MvCandidate>& candidates, double sigma_px,
                                  const MergeOptions& options);
// The same over candidates[0 .. n).
std::optional<MergedMv> MergeCell(const MvCandidate* candidates, size_t n, double sigma_px,
                                  const MergeOptions& options);

// Variance per axis of the inverse-variance merge of n_direct direct and
// n_indirect indirect IMVs: 2 sigma^2 / (2 n_direct + n_indirect).
double MergedVariance(int n_direct, int n_indirect, double sigma_px);

// Lemma 1: probability that at least one IMV exists for a macroblock, each MV
// being correct with probability p (an indirect one needs both of its vectors:
// p^2). With a direct reference (IP, PP): 1 - (1-p)(1-p^2)^n_b; without (PI):
// 1 - (1-p^2)^n_b.
double ImvExistenceProbability(bool has_direct, int n_b, double p);

// Lemma 2: expected per-axis variance of the merged MV error given that at
// least one IMV exists, averaging MergedVariance over n_direct ~ Bernoulli(p)
// (if has_direct) and n_indirect ~ Binomial(n_b, p^2). The merged error is
// zero-mean with covariance ExpectedMergedVariance * I. `min_imvs` = 2 gives
// the expectation over the cells a consensus gate accepts when a cell has
// several candidates (one IMV alone cannot be told from wrong matches).
double ExpectedMergedVariance(bool has_direct, int n_b, double p, double sigma_px,
                              int min_imvs = 1);

// Streams frames in display order and emits one AnchorPair per GOP segment.
class SegmentMerger {
 public:
  // sigma_px: the codec's MV error (StreamInfo::mv_sigma_px()).
  SegmentMerger(int width_px, int height_px, double sigma_px, MergeOptions options = {});

  // Feeds the next frame. Returns the pair (previous anchor, this anchor) when
  // `frame` is an anchor that closes a segment. Where B frames turn out to be
  // references (a B-pyramid: one decoded before a B shown earlier, see
  // StreamInfo::b_pyramid) their vectors may point to another B frame, so
  // from then on only each segment's first-decoded B frame is merged
  // (MergeOptions::pyramid_top_b; off: direct vectors only).
  std::optional<AnchorPair> Push(const FrameRecord& frame);
  void Reset();
  // `pair`, the pair just emitted, is handed back and becomes the open
  // chain: if the next segment is a one-frame P segment, its vectors are
  // composed onto `pair` and the longer pair is emitted at once, whatever
  // min_pair_span_s (a longer baseline for a pair whose one-frame parallax
  // was too small). Ignored unless `pair` ends at the current anchor, has
  // correspondences (a pair into an I frame has none: nothing to compose
  // onto) and its segment had no B frames. A next segment that cannot be
  // composed onto it (B frames, an I frame) starts at `pair`'s earlier
  // anchor without correspondences, so that consecutive pairs still share
  // their anchors. Returns whether `pair` was taken.
  bool ExtendChain(AnchorPair pair);
  // The open chain, shorter than min_pair_span_s, as a pair now (its later
  // anchor is the last one pushed), so that its frames are not left out:
  // at the stream's end, and when a B frame follows it (Push); nullopt when
  // no chain is open (or the open one is a handed-back pair, ExtendChain:
  // its caller holds it). The merger carries on from its last anchor.
  std::optional<AnchorPair> Flush();

  bool b_pyramid_seen() const { return b_pyramid_seen_; }
  int mb_cols() const { return mb_cols_; }
  int mb_rows() const { return mb_rows_; }

 private:
  int CellOf(const Eigen::Vector2d& x_px) const;  // -1 outside the frame
  // `pair` spans less than min_pair_span_s: a chain continues through it.
  // Only IPPP streams chain (no B frame seen); timestamps that do not
  // increase (a stream without them) never chain, and a chain stops at
  // kMaxChainFrames whatever its timestamps say.
  bool ShorterThanMinSpan(const AnchorPair& pair) const {
    const double dt_s = pair.later_timestamp_s - pair.earlier_timestamp_s;
    return !b_frames_seen_ && dt_s > 0 && dt_s < options_.min_pair_span_s &&
           pair.later_index - pair.earlier_index < MergeOptions::kMaxChainFrames;
  }
  AnchorPair Build(const FrameRecord& later) const;
  // The later P frame's past vectors to use as direct candidates (all of them
  // when its reference is certain; else as MergeOptions::uncertain_refs says).
  std::vector<const MotionVector*> DirectVectors(const FrameRecord& later) const;
  // The vectors of `vectors` that agree with their local field
  // (MergeOptions::uncertain_refs kConsistent).
  std::vector<const MotionVector*> ConsistentVectors(
      const std::vector<const MotionVector*>& vectors) const;
  // A B frame's vectors for indirect candidates: its future vectors, and its
  // past ones as MergeOptions::uncertain_refs says when its reference is not
  // certain (in any order: Build sorts them by block).
  std::vector<const MotionVector*> IndirectVectors(const FrameRecord& b) const;
  // Coded index of the first-decoded B frame before the anchor `later_index`,
  // -1 if none is known.
  int64_t FirstDecodedB(int64_t later_index) const;
  // Extends the chain by a one-segment P pair; returns the chained pair when
  // it is long enough.
  std::optional<AnchorPair> Chain(AnchorPair step);
  // Chained start point (in the chain's first anchor) of point x of the
  // chain's last anchor, with its variance; false where the field is empty.
  // by_cell: the chain's correspondences indexed by macroblock cell.
  bool ChainLookup(const std::vector<const Correspondence*>& by_cell, const Eigen::Vector2d& x,
                   Eigen::Vector2d* start, double* variance) const;

  int width_px_, height_px_, mb_cols_, mb_rows_;
  double sigma_px_;
  MergeOptions options_;
  std::optional<FrameRecord> earlier_;  // the last anchor (vectors dropped)
  std::vector<FrameRecord> b_frames_;   // B frames since it
  // P-frame chain: the pair from the chain's first anchor to its last one,
  // with one correspondence per macroblock cell of the last anchor (or none).
  std::optional<AnchorPair> chain_;
  bool extend_next_ = false;  // ExtendChain: emit the next composition at once
  bool last_had_b_ = false;   // the last segment closed had B frames (ExtendChain refuses it)
  bool b_pyramid_seen_ = false;
  // A B frame has been seen: the stream is not IPPP, and its P-P segments
  // (adaptive B frames) are not chained to min_pair_span_s.
  bool b_frames_seen_ = false;
};

}  // namespace slapse
