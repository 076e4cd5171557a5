#include "core/estimators/road_step.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Cholesky>

#include "core/common/road.h"
#include "core/common/so3.h"

namespace slapse {
namespace {

// One vector with what the fit needs precomputed: the earlier-anchor pixel
// it points to, the ray b = R_f K^-1 [x_f; 1], K b and f K u (the
// prediction is then p = (1 - f q^T u) / (q^T b) K b + f K u, x = p / p_z:
// a few multiplications per vector and hypothesis).
struct RoadSample {
  Eigen::Vector2d x_earlier;
  Eigen::Vector3d b, Kb, fKu;
  double fraction = 0.0;
};

RoadSample MakeSample(const Eigen::Matrix3d& K, const Eigen::Vector3d& Ku, const Eigen::Vector3d& b,
                      const Eigen::Vector2d& x_earlier, double fraction) {
  RoadSample v;
  v.x_earlier = x_earlier;
  v.b = b;
  v.Kb = K * b;
  v.fKu = fraction * Ku;
  v.fraction = fraction;
  return v;
}

// The model's pixel (file comment of road_step.h) for a hypothesis q, with
// qu = q^T u.
bool Predict(const RoadSample& v, const Eigen::Vector3d& q, double qu, Eigen::Vector2d* x) {
  const double qb = q.dot(v.b);
  const double along = 1.0 - v.fraction * qu;
  if (!(qb > 0.0) || !(along > 0.0)) return false;
  const Eigen::Vector3d p = along / qb * v.Kb + v.fKu;
  if (!(p.z() > 0.0)) return false;
  *x = p.head<2>() / p.z();
  return true;
}

// The hypothesis from two vectors. With q = B w (q^T u = 0) a road point is
// X_e ~ b + f u s, s = b^T q: the measured ray m = K^-1 [x_e; 1] parallel to
// it gives each vector's s in least squares (minimising |[m]x (b + f u s)|;
// one vector fixes only its own depth), and two vectors' (B^T b)^T w = s
// give w.
bool Hypothesis(const Eigen::Matrix3d& K_inv, const RoadSample& v0, const RoadSample& v1,
                const Eigen::Vector3d& u, const Eigen::Matrix<double, 3, 2>& B,
                Eigen::Vector3d* q) {
  Eigen::Matrix2d A;
  Eigen::Vector2d s;
  const RoadSample* both[2] = {&v0, &v1};
  for (int i = 0; i < 2; ++i) {
    const RoadSample& v = *both[i];
    const Eigen::Vector3d m = K_inv * v.x_earlier.homogeneous();
    const Eigen::Vector3d a = v.fraction * m.cross(u), c = m.cross(v.b);
    if (!(a.squaredNorm() > 0.0)) return false;
    s(i) = -a.dot(c) / a.squaredNorm();
    A.row(i) = (B.transpose() * v.b).transpose();
  }
  if (!(std::abs(A.determinant()) > 1e-12)) return false;
  *q = B * A.inverse() * s;
  return q->allFinite();
}

int CountInliers(const std::vector<RoadSample>& samples, const Eigen::Vector3d& u,
                 const Eigen::Vector3d& q, double max_px) {
  const double qu = q.dot(u);
  int count = 0;
  Eigen::Vector2d x;
  for (const RoadSample& v : samples) {
    count += Predict(v, q, qu, &x) && (x - v.x_earlier).squaredNorm() <= max_px * max_px;
  }
  return count;
}

// Gauss-Newton over w (q = B w) on the inliers' pixel residuals (Jacobian
// by central differences of Predict), re-selecting the inliers at max_px
// before each step. Fills the normal matrix J^T J (2 x 2) at the result.
Eigen::Vector3d Refine(const std::vector<RoadSample>& samples, const Eigen::Vector3d& u,
                       const Eigen::Matrix<double, 3, 2>& B, Eigen::Vector3d q, double max_px,
                       Eigen::Matrix2d* JtJ, int* inliers, double* sq_sum) {
  constexpr int kSteps = 5;
  for (int step = 0; step <= kSteps; ++step) {
    JtJ->setZero();
    Eigen::Vector2d Jtr = Eigen::Vector2d::Zero();
    *inliers = 0;
    *sq_sum = 0.0;
    const double h = 1e-6 * std::max(q.norm(), 1e-9);
    const double qu = q.dot(u);
    for (const RoadSample& v : samples) {
      Eigen::Vector2d x;
      if (!Predict(v, q, qu, &x)) continue;
      const Eigen::Vector2d r = v.x_earlier - x;
      if (r.squaredNorm() > max_px * max_px) continue;
      Eigen::Matrix2d J;
      bool ok = true;
      for (int k = 0; k < 2 && ok; ++k) {
        Eigen::Vector2d xp, xm;
        const Eigen::Vector3d qp = q + h * B.col(k), qm = q - h * B.col(k);
        ok = Predict(v, qp, qp.dot(u), &xp) && Predict(v, qm, qm.dot(u), &xm);
        J.col(k) = (xp - xm) / (2.0 * h);
      }
      if (!ok) continue;
      *JtJ += J.transpose() * J;
      Jtr += J.transpose() * r;
      *sq_sum += r.squaredNorm();
      ++*inliers;
    }
    if (step == kSteps || *inliers < 2) break;
    const Eigen::LDLT<Eigen::Matrix2d> ldlt(*JtJ);
    if (ldlt.info() != Eigen::Success) break;
    const Eigen::Vector2d delta = ldlt.solve(Jtr);
    if (!delta.allFinite()) break;
    q += B * delta;
  }
  return q;
}

}  // namespace

Status RoadStepOptions::Check(const std::string& who) const {
  if (!(inlier_px > 0.0) || !(iterations >= 1) || !(confidence > 0.0 && confidence < 1.0) ||
      !(road_max_angle_deg > 0.0 && road_max_angle_deg < 90.0) || !(min_inliers >= 3) ||
      !(sigma_px > 0.0) || !(inflation >= 1.0) || !(min_flow_px >= 0.0)) {
    return InvalidArgumentError(
        who +
        ": inlier_px must be > 0, iterations >= 1, confidence in (0, 1), road_max_angle_deg in "
        "(0, 90), min_inliers >= 3, sigma_px > 0, inflation >= 1 and min_flow_px >= 0");
  }
  return Status::Ok();
}

bool PredictRoadPixel(const Eigen::Matrix3d& K, const Eigen::Matrix3d& K_inv,
                      const Eigen::Matrix3d& R_fraction, const Eigen::Vector3d& u, double fraction,
                      const Eigen::Vector3d& q, const Eigen::Vector2d& x_frame_px,
                      Eigen::Vector2d* x_earlier_px) {
  const RoadSample v = MakeSample(K, K * u, R_fraction * (K_inv * x_frame_px.homogeneous()),
                                  Eigen::Vector2d::Zero(), fraction);
  return Predict(v, q, q.dot(u), x_earlier_px);
}

StatusOr<RoadStepReport> EstimateRoadStep(const std::vector<InterFrameVector>& vectors,
                                          const Intrinsics& intrinsics, const Eigen::Matrix3d& R,
                                          const Eigen::Vector3d& u,
                                          const RoadStepOptions& options) {
  SLAPSE_RETURN_IF_ERROR(options.Check("EstimateRoadStep"));
  if (!u.allFinite() || std::abs(u.norm() - 1.0) > 1e-6) {
    return InvalidArgumentError("EstimateRoadStep: the direction u must be a unit vector");
  }
  const Eigen::Matrix3d K = intrinsics.K(), K_inv = K.inverse();
  const Eigen::Vector3d log_R = LogSO3(R);
  const Eigen::Vector3d Ku = K * u;
  double fraction = 0.0;
  Eigen::Matrix3d R_f = Eigen::Matrix3d::Identity();
  std::vector<RoadSample> samples;
  samples.reserve(vectors.size());
  for (const InterFrameVector& iv : vectors) {
    if (!(iv.fraction > 0.0 && iv.fraction < 1.0)) {
      return InvalidArgumentError("EstimateRoadStep: a vector's fraction must be in (0, 1)");
    }
    if (iv.fraction != fraction) {  // the vectors of one frame share R_f
      fraction = iv.fraction;
      R_f = ExpSO3(fraction * log_R);
    }
    const Eigen::Vector3d b = R_f * (K_inv * iv.x_frame_px.homogeneous());
    // Rays below the earlier camera's optical axis (b_y > 0) only: the road
    // lies below it (a camera pitched down also sees the far road above its
    // axis, whose few-pixel flows say little about s). A vector shorter
    // than min_flow_px does not measure the road's depth (the encoder's
    // default where its search found nothing better, or a point at the
    // horizon): a plane far away would explain such vectors.
    const double flow_sq = (iv.x_earlier_px - iv.x_frame_px).squaredNorm();
    if (b.y() > 0.0 && !(flow_sq < options.min_flow_px * options.min_flow_px)) {
      samples.push_back(MakeSample(K, Ku, b, iv.x_earlier_px, iv.fraction));
    }
  }
  RoadStepReport report;
  if (static_cast<int>(samples.size()) < options.min_inliers) return report;

  const Eigen::Vector3d down = CameraDown();
  const Eigen::Matrix<double, 3, 2> B = TangentBasis(u);
  std::mt19937 rng(7);
  std::uniform_int_distribution<size_t> pick(0, samples.size() - 1);
  Eigen::Vector3d best_q = Eigen::Vector3d::Zero();
  int best = 0;
  // Up to `iterations` hypotheses; fewer once the best inlier share w makes
  // an all-inlier pair likely enough: log(1 - confidence) / log(1 - w^2).
  int needed = options.iterations;
  for (int it = 0; it < needed; ++it) {
    const size_t i = pick(rng), j = pick(rng);
    Eigen::Vector3d q;
    if (i == j || !Hypothesis(K_inv, samples[i], samples[j], u, B, &q)) continue;
    if (!IsRoadLike(q, down, options.road_max_angle_deg)) continue;
    const int count = CountInliers(samples, u, q, options.inlier_px);
    if (count > best) {
      best = count;
      best_q = q;
      const double w = static_cast<double>(best) / samples.size();
      const double all_inliers = w * w;
      if (all_inliers >= 1.0) break;
      needed = std::min(options.iterations,
                        static_cast<int>(std::ceil(std::log(1.0 - options.confidence) /
                                                   std::log(1.0 - all_inliers))));
    }
  }
  if (best < options.min_inliers) return report;
  Eigen::Matrix2d JtJ;
  double sq_sum = 0.0;
  const Eigen::Vector3d q =
      Refine(samples, u, B, best_q, options.inlier_px, &JtJ, &report.inliers, &sq_sum);
  const Eigen::LDLT<Eigen::Matrix2d> ldlt(JtJ);
  if (report.inliers < options.min_inliers || !IsRoadLike(q, down, options.road_max_angle_deg) ||
      ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) {
    report.inliers = 0;
    return report;
  }
  report.success = true;
  report.q = q;
  report.q_cov = options.inflation * options.sigma_px * options.sigma_px * B *
                 ldlt.solve(Eigen::Matrix2d::Identity()) * B.transpose();
  report.rms_px = std::sqrt(sq_sum / report.inliers);
  return report;
}

}  // namespace slapse
