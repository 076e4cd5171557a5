#include "core/planes/infinity.h"

#include <cmath>
#include <string>
#include <utility>

namespace slapse {

StatusOr<InfinityResult> ThresholdInfinity(const std::vector<Correspondence>& correspondences,
                                           const Intrinsics& intrinsics,
                                           const InfinityOptions& options,
                                           const PairMotionPrior* prior) {
  if (!(options.tau_inf_px > 0.0)) {
    return InvalidArgumentError("ThresholdInfinity: tau_inf_px must be > 0, got " +
                                std::to_string(options.tau_inf_px));
  }
  StatusOr<PairMotionReport> motion =
      EstimatePairMotion(correspondences, intrinsics, options, options.tau_inf_px, prior);
  if (!motion.ok()) return motion.status();
  return ThresholdInfinity(correspondences, intrinsics, options.tau_inf_px, std::move(*motion));
}

InfinityResult ThresholdInfinity(const std::vector<Correspondence>& correspondences,
                                 const Intrinsics& intrinsics, double tau_inf_px,
                                 PairMotionReport motion) {
  const int n = static_cast<int>(correspondences.size());
  const Eigen::Matrix3d K = intrinsics.K();
  const Eigen::Matrix3d K_inv = K.inverse();
  InfinityResult result;
  static_cast<PairMotionReport&>(result) = std::move(motion);
  const Eigen::Matrix3d KRKinv = K * result.R_later_from_earlier * K_inv;
  result.parallax_px.resize(n);
  for (int i = 0; i < n; ++i) {
    result.parallax_px[i] = RotationOnlyParallaxPx(KRKinv, correspondences[i]);
    if (result.parallax_px[i] >= tau_inf_px) {
      result.kept_indices.push_back(i);
    } else {
      result.dropped_indices.push_back(i);
    }
  }
  return result;
}

}  // namespace slapse
