// True motion vectors: a simulated drive's vectors replaced by where each
// block truly moved, to tell the codec's errors from the method's.
//
// Every vector of a macroblock the ground truth labels as one plane (>= 90 %
// of its pixels on it, GroundTruth::LabelAt) gets the displacement of its
// block centre transferred through that plane into the vector's reference
// frame (GroundTruth::TransferThroughPlane), plus, optionally, zero-mean
// Gaussian noise of noise_px per axis. The reference is the one the vector
// names (a P frame's or a B frame's past vector: the previous anchor; a B
// frame's future vector: the next anchor), as merging reads it. Vectors of
// mixed and unlabelled blocks (sky, several surfaces) keep the codec's
// values, as do vectors whose transfer fails (the point behind a camera).
// Nothing else of a record changes (types, texture, flags), so the pipeline
// sees the same stream with truer vectors.
//
// With noise_px = 0 a run measures the method alone: on the 48 H.264 tuning
// drives the median ATE goes 0.13 -> 0.05 % of the distance
// (docs/TRAJECTORY.md "Session 28").
#pragma once

#include <cstdint>
#include <vector>

#include "core/common/status.h"
#include "core/mv/frame_record.h"
#include "lab/gt/ground_truth.h"

namespace slapse {

struct TrueVectorOptions {
  double noise_px = 0.0;  // per axis, >= 0
  uint64_t seed = 1;      // the noise's (fixed: runs repeat)
  Status Check() const;
};

struct TrueVectorReport {
  int64_t replaced = 0;  // vectors given the true displacement
  int64_t kept = 0;      // vectors left as the codec made them
};

// Replaces the vectors of `frames` (decoded from the drive `gt` describes,
// display indices as in gt.frames) as above. InvalidArgument for bad options
// or a frame index outside the truth.
Status ReplaceWithTrueVectors(const GroundTruth& gt, const TrueVectorOptions& options,
                              std::vector<FrameRecord>* frames, TrueVectorReport* report);

}  // namespace slapse
