#include "core/eval/extraction_eval.h"

#include <algorithm>
#include <chrono>
#include <fstream>

#include "core/mv/mv_reader.h"

namespace slapse {
namespace {

double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// The video of a drive directory: meta.json names it; default drive.ts.
std::string VideoOf(const std::string& dir) {
  std::ifstream meta(dir + "/meta.json");
  std::string line;
  while (std::getline(meta, line)) {
    const size_t k = line.find("\"video\"");
    if (k == std::string::npos) continue;
    const size_t a = line.find('"', line.find(':', k) + 1), b = line.find('"', a + 1);
    if (a != std::string::npos && b != std::string::npos)
      return dir + "/" + line.substr(a + 1, b - a - 1);
  }
  return dir + "/drive.ts";
}

}  // namespace

void ExtractionStats::Add(const ExtractionStats& o) {
  pairs += o.pairs;
  planes += o.planes;
  true_positives += o.true_positives;
  visible += o.visible;
  visible_near += o.visible_near;
  found += o.found;
  found_near += o.found_near;
  merge_ms += o.merge_ms;
  threshold_ms += o.threshold_ms;
  fit_ms += o.fit_ms;
}

StatusOr<ExtractionStats> EvaluateExtraction(const std::string& drive_dir,
                                             const ExtractionEvalOptions& options) {
  auto gt = LoadGroundTruth(drive_dir);
  if (!gt.ok()) return gt.status();
  auto reader = MvReader::Open(VideoOf(drive_dir));
  if (!reader.ok()) return reader.status();
  SegmentMerger merger(gt->intrinsics.width_px, gt->intrinsics.height_px,
                       (*reader)->info().mv_sigma_px(), options.merge);
  PlaneExtractor extractor(options.extraction);
  InfinityPriorTracker prior_tracker;
  ExtractionStats stats;
  FrameRecord frame;
  Status s;
  while ((s = (*reader)->Next(&frame)).ok()) {
    if (frame.index >= static_cast<int64_t>(gt->frames.size())) {
      return FailedPreconditionError("the video has more frames than its ground truth");
    }
    auto t0 = std::chrono::steady_clock::now();
    std::optional<AnchorPair> pair = merger.Push(frame);
    if (!pair.has_value()) continue;
    stats.merge_ms += MsSince(t0);
    t0 = std::chrono::steady_clock::now();
    // As the pipeline: the previous pair's motion seeds this pair's.
    auto inf = ThresholdInfinity(pair->correspondences, gt->intrinsics, options.infinity,
                                 prior_tracker.PriorFor(*pair));
    prior_tracker.Record(*pair, inf.ok() ? &*inf : nullptr);
    stats.threshold_ms += MsSince(t0);
    if (!inf.ok()) return inf.status();
    t0 = std::chrono::steady_clock::now();
    auto extraction = extractor.Process(*pair, *inf, gt->intrinsics);
    stats.fit_ms += MsSince(t0);
    if (!extraction.ok()) return extraction.status();
    const PairPlaneEvaluation ev = EvaluatePlanes(*pair, extraction->planes, *gt, options.truth);
    if (options.planes_csv != nullptr) {
      for (size_t k = 0; k < ev.matches.size(); ++k) {
        const PlaneMatch& m = ev.matches[k];
        const ExtractedPlane& p = extraction->planes[k];
        double mean_row = 0;
        for (int mb : p.mb_indices) mean_row += mb / pair->mb_cols;
        mean_row /= std::max<size_t>(1, p.mb_indices.size());
        std::fprintf(options.planes_csv,
                     "%s,%lld,%d,%d,%zu,%.1f,%d,%s,%.3f,%.3f,%.3f,%d,%.3f,%.3f\n",
                     drive_dir.c_str(), static_cast<long long>(pair->later_index), m.track_id,
                     p.tracked ? 1 : 0, p.mb_indices.size(), mean_row, m.gt_plane,
                     m.gt_plane >= 0 ? PlaneKindName(gt->planes[m.gt_plane].kind) : "none",
                     m.purity, m.mixed_share, m.transfer_px, m.true_positive ? 1 : 0,
                     p.rms_transfer_px, p.track_change);
      }
    }
    ++stats.pairs;
    stats.planes += static_cast<int>(ev.matches.size());
    for (const PlaneMatch& m : ev.matches) stats.true_positives += m.true_positive;
    stats.visible += static_cast<int>(ev.visible.size());
    stats.visible_near += static_cast<int>(ev.visible_near.size());
    stats.found += static_cast<int>(ev.found.size());
    for (int id : ev.found) stats.found_near += ev.visible_near.count(id);
  }
  if (s.code() != StatusCode::kOutOfRange) return s;
  return stats;
}

}  // namespace slapse
