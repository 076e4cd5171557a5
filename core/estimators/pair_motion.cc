#include "core/estimators/pair_motion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/common/angles.h"
#include "core/common/so3.h"
#include "core/estimators/ransac.h"
#include "core/estimators/relative_pose.h"

namespace slapse {
namespace {

// Rotation-only model for Ransac<>: Y ~ R X for rays X (earlier camera) and Y
// (later camera), both K^{-1} [u, v, 1] (z = 1).
// Estimate: Kabsch / orthogonal Procrustes on the unit bearings, i.e. the R
// maximising sum_i yhat_i^T R xhat_i (2 points minimal, least squares for more).
// Residual: squared error on the normalised image plane z = 1,
// ||dehom(R x) - dehom(y)||^2; +infinity when (R x)_z <= 0.
struct RotationOnlyEstimator {
  using X_t = Eigen::Vector3d;
  using Y_t = Eigen::Vector3d;
  using M_t = Eigen::Matrix3d;
  static constexpr int kMinNumSamples = 2;

  static void Estimate(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                       std::vector<M_t>* models) {
    models->clear();
    if (X.size() < kMinNumSamples || X.size() != Y.size()) return;
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < X.size(); ++i) {
      M += Y[i].normalized() * X[i].normalized().transpose();
    }
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
    // Two independent directions are needed: rank(M) >= 2.
    if (!(svd.singularValues()(1) > 1e-9 * svd.singularValues()(0))) return;
    Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
    D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
    models->push_back(svd.matrixU() * D * svd.matrixV().transpose());
  }

  // Squared distance on the normalised image plane between dehom(R x_i) and
  // dehom(y_i); +infinity when R x_i is not in front (z <= 1e-12).
  static void Residuals(const std::vector<X_t>& X, const std::vector<Y_t>& Y, const M_t& R,
                        std::vector<double>* squared_residuals) {
    Scorer(X, Y).Residuals(R, squared_residuals);
  }

  // Residuals with dehom(y_i) computed once per RANSAC run: the run scores a
  // few hundred models on the same points (ransac.h's ScorerFor). The points
  // are kept as columns (structure of arrays) and scored two at a time in
  // Eigen's fixed-size packets, operation for operation as Eigen's
  // |(R x).hnormalized() - dehom(y)|^2, whose R x sums rows 0-1 as
  // (r0 x0 + r1 x1) + r2 x2 and row 2 as r0 x0 + (r1 x1 + r2 x2): the same
  // residuals, bit for bit, at two thirds of the instructions (0.56 -> 0.38 G
  // on the camera stream of docs/BENCHMARKS.md "Session 35").
  class Scorer {
   public:
    Scorer(const std::vector<X_t>& X, const std::vector<Y_t>& Y) {
      const size_t n = std::min(X.size(), Y.size());
      for (std::vector<double>* a : {&x0_, &x1_, &x2_, &y0_, &y1_}) a->resize(n);
      for (size_t i = 0; i < n; ++i) {
        x0_[i] = X[i].x();
        x1_[i] = X[i].y();
        x2_[i] = X[i].z();
        const Eigen::Vector2d y = Y[i].hnormalized();
        y0_[i] = y.x();
        y1_[i] = y.y();
      }
    }
    void Residuals(const M_t& R, std::vector<double>* squared_residuals) const {
      const size_t n = x0_.size();
      squared_residuals->resize(n);
      double* out = squared_residuals->data();
      constexpr double kInfinity = std::numeric_limits<double>::infinity();
      using Pair = Eigen::Array2d;
      auto at = [](const std::vector<double>& v, size_t i) {
        return Eigen::Map<const Pair>(&v[i]);
      };
      size_t i = 0;
      for (; i + 2 <= n; i += 2) {
        const Pair x0 = at(x0_, i), x1 = at(x1_, i), x2 = at(x2_, i);
        const Pair px = (R(0, 0) * x0 + R(0, 1) * x1) + R(0, 2) * x2;
        const Pair py = (R(1, 0) * x0 + R(1, 1) * x1) + R(1, 2) * x2;
        const Pair pz = R(2, 0) * x0 + (R(2, 1) * x1 + R(2, 2) * x2);
        const Pair dx = px / pz - at(y0_, i);
        const Pair dy = py / pz - at(y1_, i);
        const Pair sq = dx * dx + dy * dy;
        out[i] = pz(0) > 1e-12 ? sq(0) : kInfinity;
        out[i + 1] = pz(1) > 1e-12 ? sq(1) : kInfinity;
      }
      for (; i < n; ++i) {
        const double px = (R(0, 0) * x0_[i] + R(0, 1) * x1_[i]) + R(0, 2) * x2_[i];
        const double py = (R(1, 0) * x0_[i] + R(1, 1) * x1_[i]) + R(1, 2) * x2_[i];
        const double pz = R(2, 0) * x0_[i] + (R(2, 1) * x1_[i] + R(2, 2) * x2_[i]);
        const double dx = px / pz - y0_[i], dy = py / pz - y1_[i];
        out[i] = pz > 1e-12 ? dx * dx + dy * dy : kInfinity;
      }
    }

   private:
    std::vector<double> x0_, x1_, x2_, y0_, y1_;
  };
};

Status ValidateInputs(const std::vector<Correspondence>& correspondences,
                      const Intrinsics& intrinsics, const PairMotionOptions& options) {
  SLAPSE_RETURN_IF_ERROR(ValidateIntrinsics(intrinsics, "EstimatePairMotion: intrinsics"));
  SLAPSE_RETURN_IF_ERROR(options.Check("EstimatePairMotion"));
  for (size_t i = 0; i < correspondences.size(); ++i) {
    if (!correspondences[i].x_later_px.allFinite() ||
        !correspondences[i].x_earlier_px.allFinite()) {
      return InvalidArgumentError("EstimatePairMotion: correspondence " + std::to_string(i) +
                                  " has non-finite coordinates");
    }
  }
  return Status::Ok();
}

// Rotation-only outliers (off R_rot by >= min_parallax_px, or all points when
// there is no rotation model) and how many of them are E-inliers; with
// parallax_inlier_mask, which ones (per correspondence).
void CountParallax(const std::vector<Correspondence>& correspondences, const Eigen::Matrix3d& K,
                   const Eigen::Matrix3d& K_inv, const Eigen::Matrix3d* R_rot,
                   const std::vector<char>& e_inlier_mask, double min_parallax_px,
                   int* num_rotation_outliers, int* num_parallax_inliers,
                   std::vector<char>* parallax_inlier_mask = nullptr) {
  *num_rotation_outliers = *num_parallax_inliers = 0;
  if (parallax_inlier_mask != nullptr) parallax_inlier_mask->assign(correspondences.size(), 0);
  const Eigen::Matrix3d KRrot = R_rot != nullptr ? Eigen::Matrix3d(K * *R_rot * K_inv) : K;
  for (size_t i = 0; i < correspondences.size(); ++i) {
    if (R_rot != nullptr && RotationOnlyParallaxPx(KRrot, correspondences[i]) < min_parallax_px) {
      continue;
    }
    ++*num_rotation_outliers;
    *num_parallax_inliers += e_inlier_mask[i];
    if (parallax_inlier_mask != nullptr) (*parallax_inlier_mask)[i] = e_inlier_mask[i];
  }
}

// Correspondences whose Sampson distance under the essential matrix E is <=
// max_error (normalised units), counting every `stride`-th one.
int CountSampsonInliers(const std::vector<Eigen::Vector3d>& rays_earlier,
                        const std::vector<Eigen::Vector3d>& rays_later, const Eigen::Matrix3d& E,
                        double max_error, size_t stride = 1) {
  int count = 0;
  for (size_t i = 0; i < rays_earlier.size(); i += stride) {
    count += std::abs(SampsonDistance(E, rays_earlier[i], rays_later[i])) <= max_error ? 1 : 0;
  }
  return count;
}

// ... under later_from_earlier, every correspondence.
int CountSampsonInliers(const std::vector<Eigen::Vector3d>& rays_earlier,
                        const std::vector<Eigen::Vector3d>& rays_later,
                        const Rigid3d& later_from_earlier, double max_error) {
  return CountSampsonInliers(rays_earlier, rays_later,
                             Skew(later_from_earlier.translation) * later_from_earlier.R(),
                             max_error);
}

// What both paths share: the rays, K and the thresholds.
struct MotionProblem {
  MotionProblem(const std::vector<Correspondence>& c, const Intrinsics& k,
                const PairMotionOptions& o)
      : correspondences(c), intrinsics(k), options(o) {}
  const std::vector<Correspondence>& correspondences;
  const Intrinsics& intrinsics;
  const PairMotionOptions& options;
  Eigen::Matrix3d K, K_inv;
  std::vector<Eigen::Vector3d> rays_earlier, rays_later;
  double normalised_threshold = 0.0;  // ransac_threshold_px / mean focal length
  double min_parallax_px = 0.0;       // max(min_parallax_px, ransac_threshold_px)
  RansacOptions rotation_ransac;
  RelativePoseRefineOptions refine;  // both paths' Sampson refinement, at normalised_threshold
};

// Test (c') of FullPath. Wrong MVs (foliage, repeated texture, low-texture
// road) are spread over tens of pixels around any epipolar geometry, so their
// density of Sampson distances is nearly flat near it: the rotation-only
// outliers whose distance to E lies in the control band (2, 6] x threshold
// (both sides: 4x the width of the inlier band |d| <= threshold) estimate how
// many of them fall within the threshold by chance, band / 4. Genuine
// parallax points crowd into the inlier band instead. Counts the rotation-only
// outliers within the threshold (*inner) and in the band (*band).
void CountParallaxBands(const MotionProblem& p, const Eigen::Matrix3d* R_rot,
                        const Rigid3d& later_from_earlier, int* inner, int* band) {
  constexpr double kBandLo = 2.0, kBandHi = 6.0;
  *inner = *band = 0;
  const Eigen::Matrix3d E = Skew(later_from_earlier.translation) * later_from_earlier.R();
  const Eigen::Matrix3d KRrot = R_rot != nullptr ? Eigen::Matrix3d(p.K * *R_rot * p.K_inv) : p.K;
  const double thr = p.normalised_threshold;
  for (size_t i = 0; i < p.correspondences.size(); ++i) {
    if (R_rot != nullptr &&
        RotationOnlyParallaxPx(KRrot, p.correspondences[i]) < p.min_parallax_px) {
      continue;
    }
    const double d = std::abs(SampsonDistance(E, p.rays_earlier[i], p.rays_later[i]));
    if (d <= thr) {
      ++*inner;
    } else if (d > kBandLo * thr && d <= kBandHi * thr) {
      ++*band;
    }
  }
}

// Seeded fast path (a prior given and options.use_prior). The motion of
// consecutive anchor pairs changes slowly, so the previous pair's motion is a
// good start: RefineRelativePose (core/estimators/relative_pose.h:
// Levenberg-Marquardt on the Sampson distance over R and t on the unit sphere,
// with LO-style inlier re-selection at 3, 2, 1.5, 1 x ransac_threshold_px)
// refines it, and the rotation-only model is polished (LO, no random search)
// from the refined R and the prior's R instead of a full RANSAC. The result is
// accepted only if
//  - its Sampson-inlier share (|r| f_mean <= ransac_threshold_px) is at least
//    prior_min_inlier_ratio x the prior's reference_inlier_ratio (the share of
//    the last full fit, so a refinement stuck in a worse local optimum is
//    caught), and
//  - it decides has_motion = true with a margin: (a) and (b) of FullPath's
//    comment with prior_decision_margin x min_correspondences, (c) with
//    prior_decision_margin x min_parallax_inlier_ratio, and cheirality
//    counted over the parallax inliers (E-inliers off the rotation-only model
//    by >= min parallax): at least prior_decision_margin x min_correspondences
//    of them, and kMinParallaxCheiralityShare of them, in front of both
//    cameras. Points without parallax (distant facades, a highway's horizon)
//    triangulate at depths of either sign, so counting them too refused the
//    fast path where they are most of the inliers (34 of 37 pairs of the
//    highway-6 drive), although 85-99 % of the parallax points were in front.
//    The twisted-pair solution of a wrong motion puts them behind instead.
//    Their depth keeps recoverPose's bound of 50 baselines. Without it the
//    fast path was taken on most one-frame pairs of slow H.264 IPPP drives
//    (plaza-4: 4 -> 124 of 137 pairs, heading RMSE 2.6 -> 0.85 deg), but
//    also on 10 fps pairs whose full fit finds no motion (highway-2
//    h264-ippp: ATE 1.5 -> 10 %), so it stays.
// Otherwise everything is recomputed by the full path (USAC_MAGSAC, the
// rotation-only RANSAC): the fast path never decides "no motion", so the
// degenerate cases keep the full logic. With the fast path, e_inlier_mask holds
// the Sampson inliers of the refined motion and num_cheirality_inliers comes
// from CountCheirality (recoverPose's test and triangulation).
// Returns true when it was accepted and filled `result`.
constexpr double kMinParallaxCheiralityShare = 0.75;

bool SeededFastPath(const MotionProblem& p, const PairMotionPrior& prior,
                    PairMotionReport* result) {
  const int n = static_cast<int>(p.correspondences.size());
  const RelativePoseRefineReport refined =
      RefineRelativePose(p.rays_earlier, p.rays_later, prior.later_from_earlier, p.refine);
  if (!refined.success || !(refined.num_inliers >=
                            p.options.prior_min_inlier_ratio * prior.reference_inlier_ratio * n)) {
    return false;
  }
  const RansacReport<Eigen::Matrix3d> rotation =
      Ransac<RotationOnlyEstimator>(p.rotation_ransac)
          .Polish(p.rays_earlier, p.rays_later,
                  {refined.later_from_earlier.R(), prior.later_from_earlier.R()});
  int rotation_outliers = 0, parallax_inliers = 0;
  std::vector<char> parallax_mask;
  CountParallax(p.correspondences, p.K, p.K_inv, rotation.success ? &rotation.model : nullptr,
                refined.inlier_mask, p.min_parallax_px, &rotation_outliers, &parallax_inliers,
                &parallax_mask);
  const int cheirality = CountCheirality(p.rays_earlier, p.rays_later, refined.later_from_earlier,
                                         refined.inlier_mask);
  const int parallax_cheirality =
      CountCheirality(p.rays_earlier, p.rays_later, refined.later_from_earlier, parallax_mask);
  const double margin = p.options.prior_decision_margin;
  if (!(rotation.success && parallax_cheirality >= margin * p.options.min_correspondences &&
        parallax_cheirality >= kMinParallaxCheiralityShare * parallax_inliers &&
        parallax_inliers >= margin * p.options.min_correspondences &&
        parallax_inliers >=
            std::min(1.0, margin * p.options.min_parallax_inlier_ratio) * rotation_outliers)) {
    return false;
  }
  result->has_motion = true;
  result->motion_from_prior = true;
  result->rotation_source = PairRotationSource::kEssential;
  result->later_from_earlier = refined.later_from_earlier;
  result->R_later_from_earlier = refined.later_from_earlier.R();
  result->e_inlier_mask = refined.inlier_mask;
  result->num_e_inliers = refined.num_inliers;
  result->num_sampson_inliers = refined.num_inliers;
  result->num_cheirality_inliers = cheirality;
  result->num_rotation_outliers = rotation_outliers;
  result->num_parallax_inliers = parallax_inliers;
  return true;
}

// Seeds for the fast path when the prior's own rotation was refused: the
// prior's rotation R_p turned in the later camera's frame,
//   R = R_y(yaw) R_x(pitch) R_p,  yaw in [-Y, Y], pitch in [-P, P] (a grid
// of prior_scan_step_deg), with the prior's translation t_p. Each turn is
// scored by the correspondences within the refinement's widest re-selection
// threshold (3 x ransac_threshold_px, Sampson) of E = [t_p]x R, on every
// second correspondence (a count, not a fit). The best-scoring turns come
// first, each more than 1.5 grid steps from those before it (neighbours of
// one optimum are one seed). At most prior_scan_seeds; none when that is 0.
// Cost: ~225 turns x n/2 Sampson distances, a few % of one USAC_MAGSAC run.
std::vector<Rigid3d> ScannedSeeds(const MotionProblem& p, const PairMotionPrior& prior) {
  const PairMotionOptions& o = p.options;
  std::vector<Rigid3d> seeds;
  if (o.prior_scan_seeds <= 0) return seeds;
  const Eigen::Matrix3d R_p = prior.later_from_earlier.R();
  const Eigen::Vector3d t_p = prior.later_from_earlier.translation.normalized();
  const Eigen::Matrix3d t_x = Skew(t_p);
  const double wide = 3.0 * p.normalised_threshold;
  const int yaw_steps = static_cast<int>(std::floor(o.prior_scan_yaw_deg / o.prior_scan_step_deg));
  const int pitch_steps =
      static_cast<int>(std::floor(o.prior_scan_pitch_deg / o.prior_scan_step_deg));
  std::vector<std::pair<int, Eigen::Matrix3d>> scored;
  for (int i = -yaw_steps; i <= yaw_steps; ++i) {
    for (int j = -pitch_steps; j <= pitch_steps; ++j) {
      if (i == 0 && j == 0) continue;  // the prior's own rotation was refused
      const Eigen::Matrix3d R =
          Eigen::AngleAxisd(DegToRad(i * o.prior_scan_step_deg), Eigen::Vector3d::UnitY())
              .toRotationMatrix() *
          Eigen::AngleAxisd(DegToRad(j * o.prior_scan_step_deg), Eigen::Vector3d::UnitX())
              .toRotationMatrix() *
          R_p;
      scored.emplace_back(CountSampsonInliers(p.rays_earlier, p.rays_later, t_x * R, wide, 2), R);
    }
  }
  // Stable: equal counts keep the grid's order, so the seeds are deterministic.
  std::stable_sort(scored.begin(), scored.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  const double min_apart_rad = DegToRad(1.5 * o.prior_scan_step_deg);
  for (const auto& [count, R] : scored) {
    if (static_cast<int>(seeds.size()) >= o.prior_scan_seeds) break;
    bool apart = true;
    for (const Rigid3d& seed : seeds) {
      apart = apart && Eigen::AngleAxisd(seed.R() * R.transpose()).angle() > min_apart_rad;
    }
    if (apart) seeds.emplace_back(R, t_p);
  }
  return seeds;
}

// cv::recoverPose's choice among the four motions an essential matrix allows,
// (R1 or R2, +t or -t) from cv::decomposeEssentialMat: the one with the most
// E-inliers in front of both cameras within 50 baselines, the first in that
// order on a tie. The count is CountCheirality's: recoverPose's test and
// triangulation in closed form, where recoverPose's 4x4 SVD per point and
// candidate had cost a third of the pipeline on H.264 IPPP streams
// (docs/BENCHMARKS.md). Returns the count.
int ChooseMotionOfE(const MotionProblem& p, const cv::Mat& E, const std::vector<char>& e_mask,
                    Eigen::Matrix3d* R_e, Eigen::Vector3d* t_e) {
  cv::Mat R1_cv, R2_cv, t_cv;
  cv::decomposeEssentialMat(E, R1_cv, R2_cv, t_cv);
  Eigen::Matrix3d R1, R2;
  Eigen::Vector3d t;
  for (int r = 0; r < 3; ++r) {
    t(r) = t_cv.at<double>(r);
    for (int c = 0; c < 3; ++c) {
      R1(r, c) = R1_cv.at<double>(r, c);
      R2(r, c) = R2_cv.at<double>(r, c);
    }
  }
  const std::pair<const Eigen::Matrix3d*, double> candidates[] = {
      {&R1, 1.0}, {&R2, 1.0}, {&R1, -1.0}, {&R2, -1.0}};
  int best = -1;
  for (const auto& [R, sign] : candidates) {
    const int count = CountCheirality(p.rays_earlier, p.rays_later, Rigid3d(*R, sign * t), e_mask);
    if (count > best) {
      best = count;
      *R_e = *R;
      *t_e = sign * t;
    }
  }
  return best;
}

// Full path, the essential matrix (EstimatePairMotion without a prior, or
// when the prior is refused):
//   cv::findEssentialMat(x_earlier, x_later, K, cv::USAC_MAGSAC, confidence,
//   ransac_threshold_px) and recoverPose's choice of motion (ChooseMotionOfE), which give
//   later_from_earlier with |t| = 1. Pixels go in directly with K; OpenCV turns
//   the threshold into normalised units by the mean focal length. USAC_MAGSAC,
//   not cv::RANSAC: the latter returns a minimal-sample E, whose R is off by
//   ~0.1 deg on the synthetic street (0.25 px noise) -- 0.8 px of fake parallax
//   at f = 457 px, which alone pushes far points over tau_inf = 1 px. MAGSAC's
//   polished E gives ~0.01-0.02 deg. OpenCV's USAC seeds its RNG with a fixed
//   state, so the result is deterministic.
// Points1 = earlier and points2 = later, so OpenCV's (R, t) is
// later_from_earlier. Fills the E-inlier mask and cheirality count of
// `result`; *have_e when E gave a finite pose with t != 0.
Status EssentialMotion(const MotionProblem& p, PairMotionReport* result, bool* have_e,
                       Eigen::Matrix3d* R_e, Eigen::Vector3d* t_e) {
  const int n = static_cast<int>(p.correspondences.size());
  const std::vector<Correspondence>& corr = p.correspondences;
  std::vector<cv::Point2d> pts_earlier(n), pts_later(n);
  for (int i = 0; i < n; ++i) {
    pts_earlier[i] = {corr[i].x_earlier_px.x(), corr[i].x_earlier_px.y()};
    pts_later[i] = {corr[i].x_later_px.x(), corr[i].x_later_px.y()};
  }
  const Intrinsics& k = p.intrinsics;
  const cv::Mat K_cv =
      (cv::Mat_<double>(3, 3) << k.fx_px, 0, k.cx_px, 0, k.fy_px, k.cy_px, 0, 0, 1);
  *have_e = false;
  try {
    cv::Mat e_mask;
    const cv::Mat E =
        cv::findEssentialMat(pts_earlier, pts_later, K_cv, cv::USAC_MAGSAC, p.options.confidence,
                             p.options.ransac_threshold_px, 1000, e_mask);
    // findEssentialMat may stack several 3x3 solutions; the first is the best.
    if (!e_mask.empty() && e_mask.type() != CV_8U) e_mask.convertTo(e_mask, CV_8U);
    if (E.cols == 3 && E.rows >= 3 && e_mask.total() == static_cast<size_t>(n)) {
      for (int i = 0; i < n; ++i) {
        result->e_inlier_mask[i] = e_mask.at<uchar>(i) != 0 ? 1 : 0;
        result->num_e_inliers += result->e_inlier_mask[i];
      }
      result->num_cheirality_inliers =
          ChooseMotionOfE(p, E.rowRange(0, 3), result->e_inlier_mask, R_e, t_e);
      *have_e = R_e->allFinite() && t_e->allFinite() && t_e->norm() > 0.0;
    }
  } catch (const cv::Exception& e) {
    return InternalError(std::string("EstimatePairMotion: OpenCV failed: ") + e.what());
  }
  return Status::Ok();
}

// Degenerate epipolar geometry (has_motion = false, no error). With no or too
// little translation, E is undetermined (every t fits a pure rotation), and the
// R from recoverPose may be the wrong member of the twisted pair. So a
// rotation-only model is fitted as well: our Ransac<> over 2-point Kabsch fits
// on the bearing vectors, with the residual in pixels approximated as the mean
// focal length times the normalised-image-plane error. Translation counts as
// observed iff (a) cheirality holds for >= min_correspondences points, (b) at
// least min_correspondences E-inliers deviate from that rotation-only model by
// >= max(min_parallax_px, ransac_threshold_px) (parallax that E explains), and
// (c) those are at least min_parallax_inlier_ratio of all points the
// rotation-only model does not explain. (c) matters: under a pure rotation E is
// free to pick the t that makes the most *wrong* MVs look epipolar-consistent;
// with half the MVs wrong (+-32 px) that is 20-30 points with cheirality --
// above any sensible absolute count -- but < 10% of them, while genuine
// parallax points are almost all E-inliers. But (c) alone also refuses real
// motion when wrong MVs outnumber the parallax points several times (a rural
// road: foliage and low-texture asphalt give mostly wrong MVs, the road and a
// guard rail the few with parallax), so (c) may be replaced by (c'): the
// parallax points within ransac_threshold_px (Sampson) of E are at least
// min_parallax_chance_ratio times what the wrong MVs give by chance, estimated
// from their density in a control band of distances (CountParallaxBands).
// Under a pure rotation E can only gather the wrong MVs' chance share, about
// as dense inside the threshold as in the band. Otherwise has_motion = false,
// later_from_earlier = (R_rotation_only, 0) -- or the identity when even that
// fit fails or there are fewer than max(min_correspondences, 5) correspondences
// (then nothing is estimated). Tests (a)-(c) are the has_motion decision below.
// With has_motion, MAGSAC's motion is then polished by the fast path's
// RefineRelativePose (kept when it has at least as many Sampson inliers):
// MAGSAC's E is not the least-squares optimum of the Sampson distances, and
// the polished motion was closer to the truth on the tuning drives (rotation
// RMSE 0.057 -> 0.051 deg, heading 1.39 -> 0.99 deg on H.264 IPPP; 0.143 ->
// 0.136 deg and 3.07 -> 2.96 deg on MPEG-2, `bench/motion_accuracy`), so both
// paths now give the same kind of estimate.
Status FullPath(const MotionProblem& p, PairMotionReport* result) {
  result->full_fit = true;
  bool have_e = false;
  Eigen::Matrix3d R_e = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_e = Eigen::Vector3d::Zero();
  SLAPSE_RETURN_IF_ERROR(EssentialMotion(p, result, &have_e, &R_e, &t_e));
  const PairMotionOptions& o = p.options;
  // Tests (a)-(c') above against a rotation-only model: translation is
  // observed when enough E-inliers carry parallax that it cannot explain.
  auto decide = [&](const RansacReport<Eigen::Matrix3d>& rotation) {
    const Eigen::Matrix3d* R_rot = rotation.success ? &rotation.model : nullptr;
    CountParallax(p.correspondences, p.K, p.K_inv, R_rot, result->e_inlier_mask, p.min_parallax_px,
                  &result->num_rotation_outliers, &result->num_parallax_inliers);
    bool above_chance = false;
    if (have_e && o.min_parallax_chance_ratio > 0) {
      CountParallaxBands(p, R_rot, Rigid3d(R_e, t_e.normalized()),
                         &result->num_parallax_sampson_inliers, &result->num_parallax_control_band);
      const double chance = std::max(1.0, result->num_parallax_control_band / 4.0);
      above_chance = result->num_parallax_sampson_inliers >= o.min_parallax_chance_ratio * chance;
    }
    result->has_motion = have_e && result->num_cheirality_inliers >= o.min_correspondences &&
                         result->num_parallax_inliers >= o.min_correspondences &&
                         (result->num_parallax_inliers >=
                              o.min_parallax_inlier_ratio * result->num_rotation_outliers ||
                          above_chance);
  };
  // The rotation-only model where E gave a motion: polished from E's
  // rotation and its twin of the twisted pair (rotated by pi about t; under
  // a pure rotation E's own choice may be the wrong one), as the fast path
  // polishes it from the refined rotation, instead of the random search
  // (up to 2000 hypotheses, each with few inliers when the camera
  // translates: 7 % of the instructions of the 10 fps MPEG-2 drive rural-5,
  // docs/BENCHMARKS.md "Session 35"). Where that model
  // says "no motion", or the polish fails, the random search decides as
  // before: the rotation-only model is then the pair's motion.
  RansacReport<Eigen::Matrix3d> rotation;
  if (have_e) {
    const Eigen::Vector3d u = t_e.normalized();
    const Eigen::Matrix3d twin = (2.0 * u * u.transpose() - Eigen::Matrix3d::Identity()) * R_e;
    rotation = Ransac<RotationOnlyEstimator>(p.rotation_ransac)
                   .Polish(p.rays_earlier, p.rays_later, {R_e, twin});
    if (rotation.success) decide(rotation);
    result->rotation_only_from_essential = rotation.success && result->has_motion;
  }
  if (!result->rotation_only_from_essential) {
    rotation =
        Ransac<RotationOnlyEstimator>(p.rotation_ransac).Estimate(p.rays_earlier, p.rays_later);
    decide(rotation);
  }
  if (result->has_motion) {
    result->rotation_source = PairRotationSource::kEssential;
    result->later_from_earlier = Rigid3d(R_e, t_e.normalized());
    result->R_later_from_earlier = R_e;
    result->num_sampson_inliers = CountSampsonInliers(
        p.rays_earlier, p.rays_later, result->later_from_earlier, p.normalised_threshold);
    const RelativePoseRefineReport refined =
        RefineRelativePose(p.rays_earlier, p.rays_later, result->later_from_earlier, p.refine);
    if (refined.success && refined.num_inliers >= result->num_sampson_inliers) {
      result->later_from_earlier = refined.later_from_earlier;
      result->R_later_from_earlier = refined.later_from_earlier.R();
      result->num_sampson_inliers = refined.num_inliers;
    }
  } else if (rotation.success) {
    result->rotation_source = PairRotationSource::kRotationOnly;
    result->later_from_earlier = Rigid3d(rotation.model, Eigen::Vector3d::Zero());
    result->R_later_from_earlier = rotation.model;
  }
  return Status::Ok();
}

}  // namespace

Status PairMotionOptions::Check(const std::string& who) const {
  if (!(ransac_threshold_px > 0.0) || !(confidence > 0.0 && confidence < 1.0) ||
      !(min_parallax_inlier_ratio >= 0.0 && min_parallax_inlier_ratio <= 1.0) ||
      !(min_parallax_chance_ratio >= 0.0) || !(prior_min_inlier_ratio >= 0.0) ||
      !(prior_decision_margin >= 1.0) || !(prior_scan_seeds >= 0) ||
      !(prior_scan_yaw_deg >= 0.0 && prior_scan_yaw_deg <= 30.0) ||
      !(prior_scan_pitch_deg >= 0.0 && prior_scan_pitch_deg <= 30.0) ||
      !(prior_scan_step_deg >= 0.1)) {
    return InvalidArgumentError(
        who +
        ": ransac_threshold_px must be > 0, confidence in (0, 1), "
        "min_parallax_inlier_ratio in [0, 1], min_parallax_chance_ratio >= 0, "
        "prior_min_inlier_ratio >= 0, prior_decision_margin >= 1, prior_scan_seeds >= 0, "
        "prior_scan_yaw_deg and prior_scan_pitch_deg in [0, 30] and prior_scan_step_deg >= 0.1");
  }
  return Status::Ok();
}

PairMotionPath PairMotionPathOf(const PairMotionReport& report) {
  if (report.prior_rotation_scanned) return PairMotionPath::kTurnedPrior;
  if (report.motion_from_prior) return PairMotionPath::kPrior;
  return report.full_fit ? PairMotionPath::kFullFit : PairMotionPath::kNone;
}

const char* PairMotionPathName(PairMotionPath path) {
  switch (path) {
    case PairMotionPath::kPrior:
      return "prior";
    case PairMotionPath::kTurnedPrior:
      return "turned prior";
    case PairMotionPath::kFullFit:
      return "full fit";
    case PairMotionPath::kNone:
      break;
  }
  return "none";
}

double RotationOnlyParallaxPx(const Eigen::Matrix3d& KRKinv, const Correspondence& c) {
  const Eigen::Vector3d p = KRKinv * c.x_earlier_px.homogeneous();
  if (!(p.z() > 0.0)) return std::numeric_limits<double>::infinity();
  return (p.hnormalized() - c.x_later_px).norm();
}

StatusOr<PairMotionReport> EstimatePairMotion(const std::vector<Correspondence>& correspondences,
                                              const Intrinsics& intrinsics,
                                              const PairMotionOptions& options,
                                              double min_parallax_px,
                                              const PairMotionPrior* prior) {
  SLAPSE_RETURN_IF_ERROR(ValidateInputs(correspondences, intrinsics, options));
  const int n = static_cast<int>(correspondences.size());
  PairMotionReport result;
  result.e_inlier_mask.assign(n, 0);
  // The 5-point solver needs 5 points whatever min_correspondences says.
  if (n < std::max(options.min_correspondences, 5)) return result;

  MotionProblem p(correspondences, intrinsics, options);
  p.K = intrinsics.K();
  p.K_inv = p.K.inverse();
  p.rays_earlier.resize(n);
  p.rays_later.resize(n);
  for (int i = 0; i < n; ++i) {
    p.rays_earlier[i] = p.K_inv * correspondences[i].x_earlier_px.homogeneous();
    p.rays_later[i] = p.K_inv * correspondences[i].x_later_px.homogeneous();
  }
  const double mean_focal_px = 0.5 * (intrinsics.fx_px + intrinsics.fy_px);
  p.normalised_threshold = options.ransac_threshold_px / mean_focal_px;
  p.rotation_ransac.max_error = p.normalised_threshold;
  p.refine.max_error = p.normalised_threshold;
  p.rotation_ransac.confidence = options.confidence;
  // The rotation-only search scores ~2000 hypotheses (few inliers when the
  // camera translates): the pre-test (ransac.h) skips full scoring of those
  // far worse than the best on a fixed set of 100 points. Trajectories on the
  // 96 tuning drives were unchanged; full-path instructions on the camera
  // stream -20 % (docs/BENCHMARKS.md "Session 30").
  p.rotation_ransac.pretest_points = 100;
  p.min_parallax_px = std::max(min_parallax_px, options.ransac_threshold_px);

  if (prior != nullptr && options.use_prior && prior->later_from_earlier.translation.norm() > 0.0 &&
      prior->later_from_earlier.translation.allFinite()) {
    if (SeededFastPath(p, *prior, &result)) return result;
    for (const Rigid3d& seed : ScannedSeeds(p, *prior)) {
      PairMotionPrior turned = *prior;
      turned.later_from_earlier = seed;
      if (SeededFastPath(p, turned, &result)) {
        result.prior_rotation_scanned = true;
        return result;
      }
    }
  }
  SLAPSE_RETURN_IF_ERROR(FullPath(p, &result));
  return result;
}

const PairMotionPrior* PairMotionPriorTracker::PriorFor(const AnchorPair& pair) const {
  return prior_.has_value() && pair.earlier_index == later_index_ ? &*prior_ : nullptr;
}

void PairMotionPriorTracker::Record(const AnchorPair& pair, const PairMotionReport* result) {
  if (result == nullptr || !result->has_motion || pair.correspondences.empty()) {
    Reset();
    return;
  }
  const PairMotionPrior* used = PriorFor(pair);
  PairMotionPrior prior;
  prior.later_from_earlier = result->later_from_earlier;
  prior.reference_inlier_ratio =
      result->motion_from_prior && !result->prior_rotation_scanned && used != nullptr
          ? used->reference_inlier_ratio
          : static_cast<double>(result->num_sampson_inliers) / pair.correspondences.size();
  prior_ = prior;
  later_index_ = pair.later_index;
}

void PairMotionPriorTracker::Reset() {
  prior_.reset();
  later_index_ = -1;
}

}  // namespace slapse
