#include "core/pipeline/front_end.h"

#include <chrono>
#include <utility>
#include <vector>

#include "core/common/timing.h"

namespace slapse {

FrontEnd::FrontEnd(const Intrinsics& intrinsics, double sigma_px, FrontEndOptions options)
    : intrinsics_(intrinsics),
      options_(std::move(options)),
      merger_(intrinsics.width_px, intrinsics.height_px, sigma_px, options_.merge),
      extractor_(options_.extraction) {}

std::optional<FrontEndStep> FrontEnd::Push(const FrameRecord& frame) {
  const auto t0 = std::chrono::steady_clock::now();
  std::optional<AnchorPair> pair = merger_.Push(frame);
  if (!pair.has_value()) return std::nullopt;
  return Run(std::move(*pair), MsSince(t0));
}

std::optional<FrontEndStep> FrontEnd::Flush() {
  std::optional<FrontEndStep> step;
  if (std::optional<AnchorPair> pair = merger_.Flush()) step = Run(std::move(*pair), 0.0);
  Reset();
  return step;
}

FrontEndStep FrontEnd::Run(AnchorPair pair, double merge_ms) {
  FrontEndStep step;
  step.times.merge_ms = merge_ms;
  step.pair = std::move(pair);

  // Plane at infinity with the pair's motion; the previous pair's motion
  // seeds this pair's.
  auto t0 = std::chrono::steady_clock::now();
  step.infinity = ThresholdInfinity(step.pair.correspondences, intrinsics_, options_.infinity,
                                    prior_tracker_.PriorFor(step.pair));
  prior_tracker_.Record(step.pair, step.infinity.ok() ? &*step.infinity : nullptr);
  step.times.threshold_ms = MsSince(t0);

  // Planes: without a motion result, none of the pair's correspondences.
  t0 = std::chrono::steady_clock::now();
  step.extraction = step.infinity.ok() ? extractor_.Process(step.pair, *step.infinity, intrinsics_)
                                       : extractor_.Process(step.pair, std::vector<int>{});
  step.times.fit_ms = MsSince(t0);
  return step;
}

void FrontEnd::Reset() {
  merger_.Reset();
  extractor_.Reset();
  prior_tracker_.Reset();
}

}  // namespace slapse
