// The front half of the SLAPSE data path, in one place: per anchor pair,
//   SegmentMerger (paper Sec. V-A) -> pair motion with its prior and the
//   plane-at-infinity threshold (Sec. V-B) -> PlaneExtractor (Sec. V-C),
// with the wall-clock cost of each stage. The pipeline, the extraction
// evaluation, `slapse planes` and the benches all run it, so they compute the
// same motion and planes for the same stream.
//
// The previous pair's motion seeds the next pair's (the seeded fast path of
// core/estimators/pair_motion.h) when the pairs connect.
//
// A pair whose motion or thresholding fails (InvalidArgument / Internal from
// ThresholdInfinity) still goes through the extractor with no kept
// correspondence, so its tracks end as they would on a pair without parallax;
// the step carries both results and each caller decides what a failure means
// (the pipeline carries on with no planes, the evaluation stops).
#pragma once

#include <optional>

#include "core/common/camera.h"
#include "core/common/status.h"
#include "core/merge/mv_merge.h"
#include "core/mv/frame_record.h"
#include "core/planes/infinity.h"
#include "core/planes/plane_extraction.h"

namespace slapse {

struct FrontEndOptions {
  MergeOptions merge;
  InfinityOptions infinity;
  PlaneExtractionOptions extraction;
};

// Wall-clock cost of the front end's stages for one anchor pair, milliseconds.
struct FrontEndTimes {
  double merge_ms = 0, threshold_ms = 0, fit_ms = 0;
};

// One anchor pair through the front end.
struct FrontEndStep {
  AnchorPair pair;
  StatusOr<InfinityResult> infinity = InfinityResult();  // motion and kept correspondences
  StatusOr<PlaneExtractionResult> extraction = PlaneExtractionResult();
  FrontEndTimes times;
};

class FrontEnd {
 public:
  // sigma_px: the stream's MV error (StreamInfo::mv_sigma_px()).
  FrontEnd(const Intrinsics& intrinsics, double sigma_px, FrontEndOptions options = {});

  // Feeds the next frame (display order). Returns a step when the frame
  // closed an anchor pair.
  std::optional<FrontEndStep> Push(const FrameRecord& frame);

  // The stream ended: the open IPPP chain (MergeOptions::min_pair_span_s),
  // if any, goes through the front end as it is, so that its frames are not
  // left out; then as Reset(). nullopt: no chain was open.
  std::optional<FrontEndStep> Flush();

  // The stream broke off: drops the open GOP segment, the remembered planes
  // and the motion prior (track ids keep increasing).
  void Reset();

  // `pair` (the last step's) had too short a baseline: the next one-frame P
  // pair is composed onto it and emitted at once (SegmentMerger::ExtendChain),
  // and the plane extractor takes `pair` back (PlaneExtractor::Rewind), so
  // the longer pair tracks the planes of the pair before `pair`. False:
  // `pair` cannot be extended (nothing changed).
  bool ExtendBaseline(const AnchorPair& pair) {
    if (!merger_.ExtendChain(pair)) return false;
    extractor_.Rewind();
    return true;
  }

  const Intrinsics& intrinsics() const { return intrinsics_; }
  // The extractor's learnt vertical (PlaneExtractor::vertical_down).
  const Eigen::Vector3d& vertical_down() const { return extractor_.vertical_down(); }

 private:
  // Motion, plane at infinity and planes of `pair`, merged in merge_ms.
  FrontEndStep Run(AnchorPair pair, double merge_ms);

  Intrinsics intrinsics_;
  FrontEndOptions options_;
  SegmentMerger merger_;
  PairMotionPriorTracker prior_tracker_;
  PlaneExtractor extractor_;
};

}  // namespace slapse
