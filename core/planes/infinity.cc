#include "core/planes/infinity.h"

#include <cmath>
#include <string>
#include <utility>

namespace slapse {
namespace {

Status ValidateInputs(const std::vector<Correspondence>& correspondences,
                      const Intrinsics& intrinsics, const InfinityOptions& options) {
  if (!(intrinsics.fx_px > 0.0) || !(intrinsics.fy_px > 0.0) || !std::isfinite(intrinsics.fx_px) ||
      !std::isfinite(intrinsics.fy_px) || !std::isfinite(intrinsics.cx_px) ||
      !std::isfinite(intrinsics.cy_px)) {
    return InvalidArgumentError(
        "ThresholdInfinity: intrinsics need positive finite focal "
        "lengths and a finite principal point");
  }
  if (!(options.tau_inf_px > 0.0) || !options.Check().ok()) {
    return InvalidArgumentError(
        "ThresholdInfinity: thresholds must be > 0, confidence in (0, 1), "
        "min_parallax_inlier_ratio in [0, 1], prior_min_inlier_ratio >= 0 and "
        "prior_decision_margin >= 1");
  }
  for (size_t i = 0; i < correspondences.size(); ++i) {
    if (!correspondences[i].x_later_px.allFinite() ||
        !correspondences[i].x_earlier_px.allFinite()) {
      return InvalidArgumentError("ThresholdInfinity: correspondence " + std::to_string(i) +
                                  " has non-finite coordinates");
    }
  }
  return Status::Ok();
}

}  // namespace

StatusOr<InfinityResult> ThresholdInfinity(const std::vector<Correspondence>& correspondences,
                                           const Intrinsics& intrinsics,
                                           const InfinityOptions& options,
                                           const InfinityPrior* prior) {
  SLAPSE_RETURN_IF_ERROR(ValidateInputs(correspondences, intrinsics, options));
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
