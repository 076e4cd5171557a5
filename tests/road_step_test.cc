// core/estimators/road_step.h: the model's prediction against a scene built
// point by point, recovery of a known road (step length over distance and
// normal) from noisy vectors of two B frames with gross outliers and
// zero vectors, degenerate input giving no estimate, and bad input errors.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>

#include "core/common/angles.h"
#include "core/common/so3.h"
#include "core/estimators/road_step.h"

namespace slapse {
namespace {

// The step prev_from_cur (X_e = R X_l + t) and the road n^T X_e = d in the
// earlier camera: 1.6 m below a camera pitched down 3 deg, the car moving
// 2.4 m along the road over the step while turning 2 deg.
struct Scene {
  Intrinsics k = Intrinsics::FromHorizontalFov(640, 480, 70.0);
  Eigen::Matrix3d R = ExpSO3(Eigen::Vector3d(0.0, DegToRad(2.0), 0.0));
  // The camera's pitch (down: the road's normal leans towards +z).
  Eigen::Matrix3d cam_from_level = ExpSO3(Eigen::Vector3d(-DegToRad(3.0), 0.0, 0.0)).transpose();
  Eigen::Vector3d t = ExpSO3(Eigen::Vector3d(0.0, DegToRad(1.0), 0.0)) * cam_from_level *
                      Eigen::Vector3d(0.0, 0.0, 2.4);
  Eigen::Vector3d n = cam_from_level * Eigen::Vector3d::UnitY();
  double d = 1.6;
  Eigen::Vector3d q() const { return t.norm() / d * n; }
};

// The earlier-anchor pixel of the road point a frame at `fraction` sees at
// x_f, by intersecting its ray with the road (false: no intersection ahead).
bool RoadPointInEarlier(const Scene& s, double fraction, const Eigen::Vector2d& x_f,
                        Eigen::Vector2d* x_e) {
  const Eigen::Matrix3d R_f = ExpSO3(fraction * LogSO3(s.R));
  const Eigen::Vector3d centre = fraction * s.t;
  const Eigen::Vector3d ray = R_f * (s.k.K().inverse() * x_f.homogeneous());
  const double along = s.n.dot(ray);
  if (!(along > 0)) return false;
  const double lambda = (s.d - s.n.dot(centre)) / along;
  const Eigen::Vector3d X = centre + lambda * ray;
  if (!(X.z() > 0.5)) return false;
  *x_e = s.k.Project(X);
  return true;
}

// Vectors of the B frames at 1/4 and 1/2 of the step, one per 16 px block:
// road blocks with Gaussian noise, `outlier_share` of them replaced by
// vectors up to 25 px off, every 7th road block a zero vector (the
// encoder's default), and blocks above the horizon random.
std::vector<InterFrameVector> FrameVectors(const Scene& s, double noise_px, double outlier_share,
                                           std::mt19937* rng) {
  std::normal_distribution<double> noise(0.0, noise_px);
  std::uniform_real_distribution<double> off(-25.0, 25.0), unit(0.0, 1.0);
  std::vector<InterFrameVector> out;
  int road = 0;
  for (double fraction : {0.25, 0.5}) {
    for (double y = 8; y < 480; y += 16) {
      for (double x = 8; x < 640; x += 16) {
        const Eigen::Vector2d x_f(x, y);
        Eigen::Vector2d x_e;
        if (!RoadPointInEarlier(s, fraction, x_f, &x_e) || x_e.x() < 0 || x_e.x() > 640 ||
            x_e.y() < 0 || x_e.y() > 480) {
          out.push_back({x_f, x_f + Eigen::Vector2d(off(*rng), off(*rng)), fraction});
          continue;
        }
        ++road;
        if (road % 7 == 0) {
          out.push_back({x_f, x_f, fraction});
        } else if (unit(*rng) < outlier_share) {
          out.push_back({x_f, x_e + Eigen::Vector2d(off(*rng), off(*rng)), fraction});
        } else {
          out.push_back({x_f, x_e + Eigen::Vector2d(noise(*rng), noise(*rng)), fraction});
        }
      }
    }
  }
  return out;
}

TEST(RoadStepTest, PredictionEqualsTheRayThroughTheRoad) {
  const Scene s;
  const Eigen::Matrix3d K = s.k.K(), K_inv = K.inverse();
  int compared = 0;
  for (double fraction : {0.25, 0.5, 0.75}) {
    const Eigen::Matrix3d R_f = ExpSO3(fraction * LogSO3(s.R));
    for (double y = 250; y < 480; y += 37) {
      for (double x = 10; x < 640; x += 53) {
        Eigen::Vector2d truth, predicted;
        ASSERT_TRUE(RoadPointInEarlier(s, fraction, {x, y}, &truth));
        ASSERT_TRUE(
            PredictRoadPixel(K, K_inv, R_f, s.t.normalized(), fraction, s.q(), {x, y}, &predicted));
        EXPECT_LT((predicted - truth).norm(), 1e-9) << x << " " << y;
        ++compared;
      }
    }
  }
  EXPECT_GT(compared, 50);
  // A ray above the horizon misses the road.
  Eigen::Vector2d unused;
  EXPECT_FALSE(PredictRoadPixel(K, K_inv, Eigen::Matrix3d::Identity(), s.t.normalized(), 0.25,
                                s.q(), {320, 20}, &unused));
}

TEST(RoadStepTest, RecoversTheStepOverTheRoadsDistanceThroughOutliers) {
  const Scene s;
  std::mt19937 rng(3);
  const auto vectors = FrameVectors(s, 0.4, 0.3, &rng);
  const StatusOr<RoadStepReport> r = EstimateRoadStep(vectors, s.k, s.R, s.t.normalized());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_TRUE(r->success);
  const Eigen::Vector3d q = s.q();
  // 1.5 m over 1.6 m: within 1 % in length and 0.5 deg in direction.
  EXPECT_NEAR(r->q.norm() / q.norm(), 1.0, 0.01) << r->q.transpose() << " vs " << q.transpose();
  EXPECT_LT(RadToDeg(std::acos(std::min(1.0, r->q.normalized().dot(q.normalized())))), 0.5);
  EXPECT_GT(r->inliers, 300);
  EXPECT_LT(r->rms_px, 0.8);
  // q is perpendicular to the travel, and so is its covariance: positive
  // semi-definite of rank 2, nothing along u. The error is within 4 sigma
  // of it along q.
  EXPECT_LT(std::abs(r->q.dot(s.t.normalized())), 1e-12 * r->q.norm());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(r->q_cov);
  EXPECT_GT(eig.eigenvalues()(1), 0.0);
  EXPECT_LT(std::abs(eig.eigenvalues()(0)), 1e-9 * eig.eigenvalues()(2));
  EXPECT_LT((r->q_cov * s.t.normalized()).norm(), 1e-9 * eig.eigenvalues()(2));
  const Eigen::Vector3d along = q.normalized();
  EXPECT_LT(std::abs(r->q.norm() - q.norm()), 4.0 * std::sqrt(along.dot(r->q_cov * along)));
  // A wrong direction of travel (sideways by 20 deg) does not fit the
  // vectors as well: fewer inliers.
  const Eigen::Vector3d sideways = ExpSO3(Eigen::Vector3d(0, DegToRad(20), 0)) * s.t.normalized();
  const StatusOr<RoadStepReport> wrong = EstimateRoadStep(vectors, s.k, s.R, sideways);
  ASSERT_TRUE(wrong.ok());
  EXPECT_LT(wrong->inliers, r->inliers / 2);
}

TEST(RoadStepTest, NoRoadGivesNoEstimate) {
  const Scene s;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> off(-25.0, 25.0);
  std::vector<InterFrameVector> random, zero, above;
  for (double y = 8; y < 480; y += 16) {
    for (double x = 8; x < 640; x += 16) {
      const Eigen::Vector2d x_f(x, y);
      random.push_back({x_f, x_f + Eigen::Vector2d(off(rng), off(rng)), 0.25});
      zero.push_back({x_f, x_f, 0.25});  // a static scene or the encoder's default
    }
  }
  // Only the image's upper half (rays above the horizon) with the road's
  // true vectors had it been there: no ray meets a road below.
  const auto all = FrameVectors(s, 0.3, 0.0, &rng);
  for (const InterFrameVector& v : all) {
    if (v.x_frame_px.y() < 200) above.push_back(v);
  }
  for (const auto* vectors : {&random, &zero, &above}) {
    const StatusOr<RoadStepReport> r = EstimateRoadStep(*vectors, s.k, s.R, s.t.normalized());
    ASSERT_TRUE(r.ok());
    EXPECT_FALSE(r->success) << r->q.transpose() << " from " << r->inliers;
  }
  const StatusOr<RoadStepReport> empty = EstimateRoadStep({}, s.k, s.R, s.t.normalized());
  ASSERT_TRUE(empty.ok());
  EXPECT_FALSE(empty->success);
}

TEST(RoadStepTest, BadInputIsAnError) {
  const Scene s;
  const std::vector<InterFrameVector> one = {{{320, 400}, {320, 420}, 0.25}};
  EXPECT_EQ(EstimateRoadStep(one, s.k, s.R, 2.0 * s.t.normalized()).status().code(),
            StatusCode::kInvalidArgument);
  for (double fraction : {0.0, 1.0, -0.5, static_cast<double>(NAN)}) {
    const std::vector<InterFrameVector> bad = {{{320, 400}, {320, 420}, fraction}};
    EXPECT_EQ(EstimateRoadStep(bad, s.k, s.R, s.t.normalized()).status().code(),
              StatusCode::kInvalidArgument)
        << fraction;
  }
  RoadStepOptions o;
  EXPECT_TRUE(o.Check().ok());
  for (auto spoil : std::vector<void (*)(RoadStepOptions*)>{
           [](RoadStepOptions* x) { x->inlier_px = 0; },
           [](RoadStepOptions* x) { x->iterations = 0; },
           [](RoadStepOptions* x) { x->confidence = 1.0; },
           [](RoadStepOptions* x) { x->road_max_angle_deg = 90; },
           [](RoadStepOptions* x) { x->min_inliers = 2; },
           [](RoadStepOptions* x) { x->sigma_px = 0; },
           [](RoadStepOptions* x) { x->inflation = 0.5; },
           [](RoadStepOptions* x) { x->min_flow_px = -1; }}) {
    RoadStepOptions bad;
    spoil(&bad);
    EXPECT_EQ(bad.Check().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(EstimateRoadStep(one, s.k, s.R, s.t.normalized(), bad).status().code(),
              StatusCode::kInvalidArgument);
  }
}

}  // namespace
}  // namespace slapse
