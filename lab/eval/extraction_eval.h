// Plane extraction over a whole simulated drive, scored against its ground
// truth (the paper's Table I on simulated streams).
#pragma once

#include <cstdio>
#include <string>

#include "core/common/status.h"
#include "lab/eval/plane_eval.h"
#include "core/merge/mv_merge.h"
#include "core/planes/infinity.h"
#include "core/planes/plane_extraction.h"

namespace slapse {

struct ExtractionStats {
  int pairs = 0;   // anchor pairs evaluated
  int planes = 0;  // planes extracted
  int true_positives = 0;
  int visible = 0, visible_near = 0;  // true planes visible (>= 20 MBs), summed over pairs
  int found = 0, found_near = 0;      // ... of which a true positive found
  // Visible true planes that also kept >= 20 correspondences after the
  // plane-at-infinity threshold (the ones extraction could find: the others
  // lack MVs or parallax), summed over pairs, and how many were found.
  int visible_kept = 0, found_kept = 0;
  // Wall time per stage, summed over pairs (milliseconds).
  double merge_ms = 0, threshold_ms = 0, fit_ms = 0;

  double tp_rate() const { return planes > 0 ? static_cast<double>(true_positives) / planes : 0; }
  double recall() const { return visible > 0 ? static_cast<double>(found) / visible : 0; }
  double recall_near() const {
    return visible_near > 0 ? static_cast<double>(found_near) / visible_near : 0;
  }
  double recall_kept() const {
    return visible_kept > 0 ? static_cast<double>(found_kept) / visible_kept : 0;
  }
  void Add(const ExtractionStats& o);
};

struct ExtractionEvalOptions {
  MergeOptions merge;
  InfinityOptions infinity;
  PlaneExtractionOptions extraction;
  PlaneTruthOptions truth;
  // If set, one CSV row per extracted plane is appended here (for studying
  // the false positives): drive, pair, plane and its scores.
  std::FILE* planes_csv = nullptr;
};

// Reads `drive_dir` (a `slapse simulate` output: video + ground truth), runs
// merging, thresholding and extraction on every anchor pair and scores it.
StatusOr<ExtractionStats> EvaluateExtraction(const std::string& drive_dir,
                                             const ExtractionEvalOptions& options);

}  // namespace slapse
