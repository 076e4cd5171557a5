// Relative-pose refinement from a prior (core/estimators/relative_pose.h): the
// Sampson residual's and E's Jacobians against finite differences, recovery of
// the true motion from a perturbed guess on synthetic correspondences, and
// the cheirality count (against cv::recoverPose's).
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/common/angles.h"
#include "core/common/rigid3.h"
#include "core/common/so3.h"
#include "core/estimators/relative_pose.h"

namespace slapse {
namespace {

const double kDegToRad = DegToRad(1.0);
constexpr double kFocalPx = 457.0;

double AngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle() / kDegToRad;
}

// Forward 1 m with a small turn: X_later = R X_earlier + t.
Rigid3d TrueMotion() {
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(1.5 * kDegToRad, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(-0.4 * kDegToRad, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  return Rigid3d(R, Eigen::Vector3d(0.05, 0.02, -1.0));
}

struct Rays {
  std::vector<Eigen::Vector3d> earlier, later;  // z = 1
  std::vector<char> wrong;                      // per ray pair: a wrong correspondence
};

// Points 4-60 m ahead of the earlier camera seen in both; `sigma_px` noise on
// the later pixel, a share `outlier_ratio` of them replaced by random offsets.
Rays MakeRays(const Rigid3d& later_from_earlier, int n, double sigma_px, double outlier_ratio,
              uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> xy(-0.6, 0.6), depth(4.0, 60.0), unit(0.0, 1.0),
      wrong_px(-30.0, 30.0);
  std::normal_distribution<double> noise(0.0, sigma_px / kFocalPx);
  Rays rays;
  while (static_cast<int>(rays.earlier.size()) < n) {
    const Eigen::Vector3d ray_e(xy(rng), xy(rng), 1.0);
    const Eigen::Vector3d X_l = later_from_earlier * (depth(rng) * ray_e);
    if (X_l.z() < 1.0) continue;
    Eigen::Vector3d ray_l = X_l / X_l.z();
    const bool wrong = unit(rng) < outlier_ratio;
    if (wrong) {
      ray_l.head<2>() += Eigen::Vector2d(wrong_px(rng), wrong_px(rng)) / kFocalPx;
    } else {
      ray_l.head<2>() += Eigen::Vector2d(noise(rng), noise(rng));
    }
    rays.earlier.push_back(ray_e);
    rays.later.push_back(ray_l);
    rays.wrong.push_back(wrong);
  }
  return rays;
}

// Rigid3d keeps its rotation a unit quaternion (core/common/rigid3.h): a
// quaternion 1e-4 too long, or a matrix scaled by as much, composed 1000
// times stays a rotation, and the composition's inverse undoes it. Without
// the normalisation the norm grows by 1e-4 per composition (x1.1 here).
TEST(Rigid3dTest, RotationStaysUnitThroughCompositions) {
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.01, Eigen::Vector3d(1, 2, 3).normalized()));
  const Rigid3d step(Eigen::Quaterniond(q.coeffs() * (1.0 + 1e-4)), Eigen::Vector3d(0.1, 0, 1));
  const Rigid3d step_m(Eigen::Matrix3d(q.toRotationMatrix() * (1.0 + 1e-4)),
                       Eigen::Vector3d(0.1, 0, 1));
  Rigid3d pose, pose_m;
  for (int i = 0; i < 1000; ++i) {
    pose = pose * step;
    pose_m = pose_m * step_m;
  }
  EXPECT_NEAR(pose.rotation.norm(), 1.0, 1e-12);
  EXPECT_NEAR(pose_m.rotation.norm(), 1.0, 1e-12);
  const Rigid3d identity = pose.Inverse() * pose;
  EXPECT_LT(identity.translation.norm(), 1e-9);
  EXPECT_LT(identity.rotation.angularDistance(Eigen::Quaterniond::Identity()), 1e-12);
  // A step's length is its translation's, in either frame.
  EXPECT_NEAR((pose.Inverse() * (pose * step)).translation.norm(), step.translation.norm(), 1e-9);
}

TEST(RelativePoseTest, SampsonGradientMatchesFiniteDifferences) {
  const Rigid3d motion = TrueMotion();
  const Eigen::Matrix3d E = Skew(motion.translation) * motion.R();
  const Rays rays = MakeRays(motion, 20, 2.0, 0.3, 1);
  for (size_t i = 0; i < rays.earlier.size(); ++i) {
    Eigen::Matrix<double, 1, 9> analytic;
    SampsonDistance(E, rays.earlier[i], rays.later[i], &analytic);
    for (int k = 0; k < 9; ++k) {
      const double h = 1e-7;
      Eigen::Matrix3d plus = E, minus = E;
      plus(k / 3, k % 3) += h;
      minus(k / 3, k % 3) -= h;
      const double numeric = (SampsonDistance(plus, rays.earlier[i], rays.later[i]) -
                              SampsonDistance(minus, rays.earlier[i], rays.later[i])) /
                             (2 * h);
      EXPECT_NEAR(analytic(k), numeric, 1e-6 * (1.0 + std::abs(numeric))) << i << " " << k;
    }
  }
}

TEST(RelativePoseTest, EssentialJacobianMatchesFiniteDifferences) {
  const Rigid3d motion = TrueMotion();
  const Eigen::Matrix3d R = motion.R();
  const Eigen::Vector3d t = motion.translation.normalized();
  const Eigen::Matrix<double, 3, 2> basis = TangentBasis(t);
  EXPECT_NEAR(basis.col(0).dot(t), 0.0, 1e-12);
  EXPECT_NEAR(basis.col(1).dot(t), 0.0, 1e-12);
  EXPECT_NEAR(basis.col(0).dot(basis.col(1)), 0.0, 1e-12);
  // E(theta, delta) = [normalize(t + B delta)]x R Exp(theta).
  auto essential = [&](const Eigen::Matrix<double, 5, 1>& p) {
    const Eigen::Vector3d t_p = (t + basis * p.tail<2>()).normalized();
    return Eigen::Matrix3d(Skew(t_p) * R * ExpSO3(p.head<3>()));
  };
  const Eigen::Matrix<double, 9, 5> analytic = EssentialJacobian(R, t, basis);
  for (int k = 0; k < 5; ++k) {
    const double h = 1e-6;
    Eigen::Matrix<double, 5, 1> plus = Eigen::Matrix<double, 5, 1>::Zero(), minus = plus;
    plus(k) = h;
    minus(k) = -h;
    const Eigen::Matrix3d dE = (essential(plus) - essential(minus)) / (2 * h);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(analytic(3 * i + j, k), dE(i, j), 1e-8);
    }
  }
}

TEST(RelativePoseTest, RefineRecoversTrueMotionFromPerturbedPrior) {
  const Rigid3d truth = TrueMotion();
  const Rays rays = MakeRays(truth, 800, 0.25, 0.2, 2);
  // The previous pair's motion, say: 1 deg of rotation and ~6 deg of heading off.
  const Rigid3d prior(truth.R() * ExpSO3(Eigen::Vector3d(0.6, -0.5, 0.6) * kDegToRad),
                      truth.translation + Eigen::Vector3d(0.1, -0.03, 0.0));
  RelativePoseRefineOptions options;
  options.max_error = 1.0 / kFocalPx;
  const RelativePoseRefineReport report =
      RefineRelativePose(rays.earlier, rays.later, prior, options);
  ASSERT_TRUE(report.success);
  EXPECT_LT(AngleDeg(report.later_from_earlier.R(), truth.R()), 0.02);
  EXPECT_NEAR(report.later_from_earlier.translation.norm(), 1.0, 1e-12);
  EXPECT_GT(report.later_from_earlier.translation.dot(truth.translation.normalized()),
            std::cos(0.3 * kDegToRad));
  int good = 0, good_in = 0, wrong_in = 0;
  for (size_t i = 0; i < rays.wrong.size(); ++i) {
    if (rays.wrong[i]) {
      wrong_in += report.inlier_mask[i];
    } else {
      ++good;
      good_in += report.inlier_mask[i];
    }
  }
  EXPECT_GE(good_in, 0.95 * good);  // 1 px at 0.25 px noise (Sampson ~ 1D): > 99 % expected
  EXPECT_LE(wrong_in, 0.1 * (rays.wrong.size() - good));
  EXPECT_EQ(report.num_inliers, good_in + wrong_in);

  // Deterministic.
  const RelativePoseRefineReport again =
      RefineRelativePose(rays.earlier, rays.later, prior, options);
  EXPECT_EQ(again.inlier_mask, report.inlier_mask);
  EXPECT_EQ(again.later_from_earlier.translation, report.later_from_earlier.translation);
}

TEST(RelativePoseTest, BadPriorExplainsFarFewerPoints) {
  // A prior that is not near the truth ends in a poor local optimum (or fails):
  // its inlier count is what callers check against a full fit's.
  const Rigid3d truth = TrueMotion();
  const Rays rays = MakeRays(truth, 800, 0.25, 0.2, 3);
  RelativePoseRefineOptions options;
  options.max_error = 1.0 / kFocalPx;
  const RelativePoseRefineReport good =
      RefineRelativePose(rays.earlier, rays.later, truth, options);
  ASSERT_TRUE(good.success);
  const Rigid3d sideways(truth.R() * ExpSO3(Eigen::Vector3d(0, 25, 0) * kDegToRad),
                         Eigen::Vector3d(1.0, 0.0, 0.2));
  const RelativePoseRefineReport bad =
      RefineRelativePose(rays.earlier, rays.later, sideways, options);
  EXPECT_LT(bad.num_inliers, 0.8 * good.num_inliers);
}

TEST(RelativePoseTest, DegenerateInputFails) {
  RelativePoseRefineOptions options;
  options.max_error = 1.0 / kFocalPx;
  const Rays rays = MakeRays(TrueMotion(), 4, 0.25, 0.0, 4);
  EXPECT_FALSE(RefineRelativePose(rays.earlier, rays.later, TrueMotion(), options).success);
  const Rays more = MakeRays(TrueMotion(), 50, 0.25, 0.0, 4);
  EXPECT_FALSE(RefineRelativePose(more.earlier, more.later,
                                  Rigid3d(TrueMotion().R(), Eigen::Vector3d::Zero()), options)
                   .success);
  options.max_error = 0.0;
  EXPECT_FALSE(RefineRelativePose(more.earlier, more.later, TrueMotion(), options).success);
}

TEST(RelativePoseTest, CheiralityCountsPointsInFront) {
  const Rigid3d truth = TrueMotion();
  const Rays rays = MakeRays(truth, 300, 0.0, 0.0, 5);
  const Rigid3d unit(truth.rotation, truth.translation.normalized());
  // Depths up to ~60 m over |t| ~ 1 m: all but those beyond 50 units.
  const int in_front = CountCheirality(rays.earlier, rays.later, unit, {});
  EXPECT_GT(in_front, 200);
  EXPECT_EQ(CountCheirality(rays.earlier, rays.later, unit, {}, 1e9), 300);
  const Rigid3d flipped(truth.rotation, -unit.translation);
  EXPECT_EQ(CountCheirality(rays.earlier, rays.later, flipped, {}, 1e9), 0);
  std::vector<char> mask(300, 0);
  mask[0] = mask[1] = 1;
  EXPECT_LE(CountCheirality(rays.earlier, rays.later, unit, mask, 1e9), 2);
}

// cv::recoverPose's count for E = [t]x R: its best of the four motions E
// allows, each point triangulated by an SVD.
int RecoverPoseCount(const Rays& rays, const Rigid3d& motion) {
  const Eigen::Matrix3d E = Skew(motion.translation.normalized()) * motion.R();
  cv::Mat E_cv(3, 3, CV_64F);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) E_cv.at<double>(r, c) = E(r, c);
  }
  std::vector<cv::Point2d> earlier, later;
  for (size_t i = 0; i < rays.earlier.size(); ++i) {
    earlier.emplace_back(rays.earlier[i].x(), rays.earlier[i].y());
    later.emplace_back(rays.later[i].x(), rays.later[i].y());
  }
  cv::Mat R_cv, t_cv;
  return cv::recoverPose(E_cv, earlier, later, cv::Mat::eye(3, 3, CV_64F), R_cv, t_cv);
}

// The same choice made with CountCheirality.
int BestCheirality(const Rays& rays, const Rigid3d& motion) {
  const Eigen::Vector3d t = motion.translation.normalized();
  // E's other rotation: the twisted pair, rotated by 180 deg about t.
  const Eigen::Matrix3d twisted = Eigen::AngleAxisd(M_PI, t).toRotationMatrix() * motion.R();
  int best = 0;
  for (const Eigen::Matrix3d& R : {motion.R(), twisted}) {
    for (const double sign : {1.0, -1.0}) {
      best = std::max(best, CountCheirality(rays.earlier, rays.later, Rigid3d(R, sign * t), {}));
    }
  }
  return best;
}

// Points without parallax (a pure rotation's, with noise) are not in front:
// the linear triangulation puts them near infinity. A least-squares fit of the
// depths along both rays had counted 2-4 % of them.
TEST(RelativePoseTest, CheiralityMatchesRecoverPose) {
  const Rigid3d truth = TrueMotion();
  const Rigid3d rotation_only(truth.rotation, Eigen::Vector3d::Zero());
  const Eigen::Vector3d directions[] = {{0.0, 0.0, -1.0}, {0.6, 0.1, -0.8}, {1.0, 0.0, 0.0}};
  for (const uint64_t seed : {11u, 12u, 13u}) {
    const Rays moving = MakeRays(truth, 2000, 0.5, 0.2, seed);
    const int count = BestCheirality(moving, truth);
    EXPECT_GT(count, 1000) << "seed " << seed;
    // Equal up to a few wrong correspondences (30 px off) on which the
    // restriction to the earlier ray decides differently.
    EXPECT_NEAR(count, RecoverPoseCount(moving, truth), 0.005 * count) << "seed " << seed;

    const Rays rotating = MakeRays(rotation_only, 2000, 0.3, 0.0, seed);
    for (const Eigen::Vector3d& t : directions) {
      const Rigid3d fitted(truth.rotation, t);
      const int noise_count = BestCheirality(rotating, fitted);
      EXPECT_LE(noise_count, 10) << "seed " << seed << ", t " << t.transpose();
      EXPECT_NEAR(noise_count, RecoverPoseCount(rotating, fitted), 2)
          << "seed " << seed << ", t " << t.transpose();
    }
  }
}

}  // namespace
}  // namespace slapse
