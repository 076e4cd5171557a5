// core/estimators/frame_pose.h: the residual's Jacobian against central
// finite differences on the estimator's own manifold, recovery of a known
// pose from noisy vectors on two planes (with gross outliers), and degenerate
// input (too few vectors, all on one point) giving no model.
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/so3.h"
#include "core/estimators/frame_pose.h"

namespace slapse {
namespace {

Intrinsics TestCamera() { return Intrinsics::FromHorizontalFov(640, 480, 70.0); }

// A camera 1.5 m above a road (y down, so the road is y = 1.5 in the world
// of the first camera) with a facade at x = 6 m; observations of points of
// both planes seen from `truth`, with Gaussian pixel noise.
std::vector<FramePoseObservation> PlaneObservations(const Intrinsics& k, const Rigid3d& truth,
                                                    double noise_px, std::mt19937* rng) {
  std::normal_distribution<double> noise(0.0, noise_px);
  std::vector<FramePoseObservation> out;
  const Rigid3d cam_from_world = truth.Inverse();
  auto add = [&](const Eigen::Vector3d& x_w) {
    const Eigen::Vector3d x_c = cam_from_world * x_w;
    if (x_c.z() < 1.0) return;
    const Eigen::Vector2d px = k.Project(x_c);
    if (px.x() < 0 || px.y() < 0 || px.x() > k.width_px || px.y() > k.height_px) return;
    FramePoseObservation ob;
    ob.point_world = x_w;
    ob.x_px = px + Eigen::Vector2d(noise(*rng), noise(*rng));
    ob.variance_px2 = noise_px * noise_px;
    out.push_back(ob);
  };
  for (double z = 4; z < 40; z += 1.5) {
    for (double x = -5; x < 5.5; x += 1.0) add({x, 1.5, z});  // road
    for (double y = -4; y < 1.5; y += 0.8) add({6.0, y, z});  // facade
  }
  return out;
}

Rigid3d TruePose() {
  return Rigid3d(Eigen::Quaterniond(ExpSO3(Eigen::Vector3d(0.01, 0.05, -0.02))),
                 Eigen::Vector3d(0.2, -0.05, 3.0));
}

TEST(FramePoseTest, JacobianMatchesFiniteDifferences) {
  const Intrinsics k = TestCamera();
  std::mt19937 rng(7);
  const Rigid3d pose = TruePose();
  const auto obs = PlaneObservations(k, pose, 0.5, &rng);
  ASSERT_GT(obs.size(), 50u);
  for (size_t i = 0; i < obs.size(); i += 17) {
    Eigen::Vector2d r;
    Eigen::Matrix<double, 2, 6> J;
    ASSERT_TRUE(FramePoseResidual(k, pose, obs[i], &r, &J));
    const double h = 1e-6;
    for (int c = 0; c < 6; ++c) {
      Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
      d(c) = h;
      Eigen::Vector2d rp, rm;
      ASSERT_TRUE(FramePoseResidual(k, RetractFramePose(pose, d), obs[i], &rp, nullptr));
      ASSERT_TRUE(FramePoseResidual(k, RetractFramePose(pose, -d), obs[i], &rm, nullptr));
      const Eigen::Vector2d fd = (rp - rm) / (2 * h);
      EXPECT_NEAR((fd - J.col(c)).norm(), 0.0, 1e-4 * (1.0 + fd.norm()))
          << "observation " << i << " column " << c;
    }
  }
}

TEST(FramePoseTest, RecoversThePoseFromNoisyVectorsWithOutliers) {
  const Intrinsics k = TestCamera();
  std::mt19937 rng(11);
  const Rigid3d truth = TruePose();
  auto obs = PlaneObservations(k, truth, 0.5, &rng);
  // One in eight vectors is a wrong match (off by 5-20 px).
  std::uniform_real_distribution<double> off(5.0, 20.0);
  int outliers = 0;
  for (size_t i = 0; i < obs.size(); i += 8, ++outliers) obs[i].x_px.x() += off(rng);
  // The prior (the anchors' interpolation) is off by 0.3 m and 1 degree.
  const Rigid3d prior(truth.R() * ExpSO3(Eigen::Vector3d(0.0, 0.017, 0.0)),
                      truth.translation + Eigen::Vector3d(0.1, 0.05, 0.28));
  FramePoseOptions o;
  o.extra_sigma_px = 0.0;
  o.prior_rotation_rad = 0.0;  // data only: the prior must not be what lands it
  o.prior_position_rel = 0.0;
  ASSERT_TRUE(o.Check().ok());
  FramePoseReport rep;
  const auto pose = EstimateFramePose(k, obs, prior, 1.0, o, &rep);
  ASSERT_TRUE(pose.has_value()) << rep.no_model_reason;
  const double pos_err = (pose->translation - truth.translation).norm();
  const double rot_err = LogSO3(truth.R().transpose() * pose->R()).norm();
  EXPECT_LT(pos_err, 0.03);
  EXPECT_LT(rot_err, 0.002);
  EXPECT_GE(rep.inliers, static_cast<int>(obs.size()) - outliers - 5);
  EXPECT_LE(rep.inliers, static_cast<int>(obs.size()) - outliers + 2);
  EXPECT_LT(rep.rms_px, 1.0);
  // The covariance is consistent with the error (within 5 sigma) and not absurdly loose.
  EXPECT_GT(rep.position_sigma, 0.0);
  EXPECT_LT(pos_err, 5 * rep.position_sigma + 1e-3);
  EXPECT_LT(rep.position_sigma, 0.05);
}

TEST(FramePoseTest, TooFewVectorsIsNoModel) {
  const Intrinsics k = TestCamera();
  std::mt19937 rng(3);
  auto obs = PlaneObservations(k, TruePose(), 0.5, &rng);
  obs.resize(10);
  FramePoseReport rep;
  EXPECT_FALSE(EstimateFramePose(k, obs, TruePose(), 1.0, FramePoseOptions(), &rep).has_value());
  EXPECT_NE(rep.no_model_reason.find("too few"), std::string::npos) << rep.no_model_reason;
}

TEST(FramePoseTest, VectorsOfOnePointDoNotConstrainThePose) {
  const Intrinsics k = TestCamera();
  std::mt19937 rng(5);
  auto obs = PlaneObservations(k, TruePose(), 0.5, &rng);
  ASSERT_GT(obs.size(), 50u);
  for (auto& ob : obs) ob = obs.front();  // 2 equations, 6 unknowns
  FramePoseOptions o;
  o.prior_rotation_rad = 0.01;  // a prior makes it solvable, but not from the data
  o.prior_position_rel = 0.1;
  FramePoseReport rep;
  EXPECT_FALSE(EstimateFramePose(k, obs, TruePose(), 1.0, o, &rep).has_value());
  EXPECT_NE(rep.no_model_reason.find("six"), std::string::npos) << rep.no_model_reason;
}

TEST(FramePoseTest, OptionsCheckRejectsBadValues) {
  FramePoseOptions o;
  EXPECT_TRUE(o.Check().ok());
  o.min_inliers = 3;
  EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument);
  o = FramePoseOptions();
  o.huber_k = 0;
  EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument);
  o = FramePoseOptions();
  o.min_information_ratio = 1.0;
  EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace slapse
