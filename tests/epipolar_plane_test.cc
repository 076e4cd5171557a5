// The motion-constrained plane estimator (core/estimators/epipolar_plane.h):
// exact minimal solutions, weighted least squares under noise, degenerate
// samples, residuals equal to the transfer error of H = K (R + t m^T) K^-1,
// and RANSAC over two planes with outliers. Fixed seeds.
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/common/angles.h"
#include "core/estimators/epipolar_plane.h"
#include "core/estimators/homography.h"
#include "core/estimators/ransac.h"

namespace slapse {
namespace {

using Points = std::vector<Eigen::Vector2d>;

Intrinsics Camera() {
  Intrinsics k;
  k.fx_px = 457;
  k.fy_px = 457;
  k.cx_px = 319.5;
  k.cy_px = 239.5;
  k.width_px = 640;
  k.height_px = 480;
  return k;
}

// A forward step with a little yaw: X_earlier = R X_later + t.
Rigid3d EarlierFromLater() {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.02, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                            Eigen::AngleAxisd(-0.01, Eigen::Vector3d::UnitX()).toRotationMatrix();
  return Rigid3d(R, Eigen::Vector3d(0.05, 0.02, -1.0));
}

// A facade on the right, 6 (step units) to the side: n = (1, 0, -0.1) / |.|.
Eigen::Vector3d FacadeM() { return Eigen::Vector3d(1.0, 0.0, -0.1).normalized() / 6.0; }
// The road 1.5 below the camera (y down): n = (0, 1, 0), d = 1.5.
Eigen::Vector3d RoadM() { return Eigen::Vector3d(0.0, 1.0, 0.0) / 1.5; }

// Later pixels on a grid of MB centres inside [u0, u1) x [v0, v1) and their
// earlier pixels through the plane m, plus isotropic noise.
void MakePlanePoints(const Eigen::Vector3d& m, double u0, double u1, double v0, double v1,
                     double noise_px, std::mt19937_64& rng, Points* later, Points* earlier) {
  const Eigen::Matrix3d H = EpipolarPlaneEstimator::Homography(m, Camera(), EarlierFromLater());
  std::normal_distribution<double> n(0.0, noise_px);
  for (double v = v0 + 7.5; v < v1; v += 16) {
    for (double u = u0 + 7.5; u < u1; u += 16) {
      later->push_back({u, v});
      earlier->push_back((H * Eigen::Vector3d(u, v, 1)).hnormalized() +
                         Eigen::Vector2d(n(rng), n(rng)));
    }
  }
}

std::vector<EpipolarPlanePoint> Prepare(const Points& later) {
  return EpipolarPlaneEstimator::Prepare(later, Camera(), EarlierFromLater());
}

TEST(EpipolarPlaneEstimatorTest, MinimalSampleIsExact) {
  std::mt19937_64 rng(1);
  Points later, earlier;
  MakePlanePoints(FacadeM(), 400, 640, 0, 300, 0.0, rng, &later, &earlier);
  ASSERT_GE(later.size(), 3u);
  const Points l3 = {later[0], later[7], later[later.size() - 1]};
  const Points e3 = {earlier[0], earlier[7], earlier[earlier.size() - 1]};
  std::vector<Eigen::Vector3d> models;
  EpipolarPlaneEstimator::Estimate(Prepare(l3), e3, &models);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_LT((models[0] - FacadeM()).norm(), 1e-9 * FacadeM().norm());
  // Every point of the plane has zero residual.
  std::vector<double> r;
  EpipolarPlaneEstimator::Residuals(Prepare(later), earlier, models[0], &r);
  for (double x : r) EXPECT_LT(x, 1e-16);
}

TEST(EpipolarPlaneEstimatorTest, ResidualIsTransferErrorOfItsHomography) {
  std::mt19937_64 rng(2);
  Points later, earlier;
  MakePlanePoints(RoadM(), 0, 640, 300, 480, 0.7, rng, &later, &earlier);
  const Eigen::Vector3d m = RoadM() * 1.1;  // a slightly wrong plane: non-zero residuals
  std::vector<double> r_plane, r_h;
  EpipolarPlaneEstimator::Residuals(Prepare(later), earlier, m, &r_plane);
  HomographyEstimator::Residuals(
      later, earlier, EpipolarPlaneEstimator::Homography(m, Camera(), EarlierFromLater()), &r_h);
  ASSERT_EQ(r_plane.size(), r_h.size());
  for (size_t i = 0; i < r_h.size(); ++i) EXPECT_NEAR(r_plane[i], r_h[i], 1e-9 * (1 + r_h[i]));
}

TEST(EpipolarPlaneEstimatorTest, PlaneBehindTheCameraHasInfiniteResiduals) {
  std::mt19937_64 rng(3);
  Points later, earlier;
  MakePlanePoints(RoadM(), 0, 640, 300, 480, 0.0, rng, &later, &earlier);
  std::vector<double> r;
  // The road's mirror image above the camera: its points would be behind it
  // (rho = m . r < 0 below the horizon).
  EpipolarPlaneEstimator::Residuals(Prepare(later), earlier, -RoadM(), &r);
  for (double x : r) EXPECT_EQ(x, std::numeric_limits<double>::infinity());
}

// Ransac<>'s vectorised scorer gives exactly Residuals' values, also for
// points behind the camera (+infinity) and odd counts (a scalar tail).
TEST(EpipolarPlaneEstimatorTest, ScorerEqualsResiduals) {
  std::mt19937_64 rng(4);
  Points later, earlier;
  MakePlanePoints(RoadM(), 0, 640, 300, 480, 0.7, rng, &later, &earlier);
  MakePlanePoints(FacadeM(), 400, 640, 0, 300, 0.7, rng, &later, &earlier);
  if (later.size() % 2 == 0) {  // one more, for an odd count
    later.push_back({320, 100});
    earlier.push_back({321, 99});
  }
  const std::vector<EpipolarPlanePoint> X = Prepare(later);
  const EpipolarPlaneEstimator::Scorer scorer(X, earlier);
  for (const Eigen::Vector3d& m : {RoadM(), FacadeM(), Eigen::Vector3d(RoadM() * 1.1),
                                   Eigen::Vector3d(-RoadM()), Eigen::Vector3d::Zero().eval()}) {
    std::vector<double> expected, actual;
    EpipolarPlaneEstimator::Residuals(X, earlier, m, &expected);
    scorer.Residuals(m, &actual);
    ASSERT_EQ(actual.size(), expected.size());
    for (size_t i = 0; i < expected.size(); ++i) EXPECT_EQ(actual[i], expected[i]) << i;
  }
}

TEST(EpipolarPlaneEstimatorTest, LeastSquaresUnderNoiseIsCloseToTheTruth) {
  std::mt19937_64 rng(4);
  Points later, earlier;
  MakePlanePoints(FacadeM(), 400, 640, 0, 300, 0.5, rng, &later, &earlier);
  std::vector<Eigen::Vector3d> models;
  EpipolarPlaneEstimator::Estimate(Prepare(later), earlier, &models);
  ASSERT_EQ(models.size(), 1u);
  // The fit transfers like the true plane to well within the noise: its mean
  // transfer difference over the plane's own points is far below 0.5 px.
  const Eigen::Matrix3d H_fit =
      EpipolarPlaneEstimator::Homography(models[0], Camera(), EarlierFromLater());
  const Eigen::Matrix3d H_true =
      EpipolarPlaneEstimator::Homography(FacadeM(), Camera(), EarlierFromLater());
  double sum = 0;
  for (const auto& x : later) {
    sum +=
        ((H_fit * x.homogeneous()).hnormalized() - (H_true * x.homogeneous()).hnormalized()).norm();
  }
  EXPECT_LT(sum / later.size(), 0.15);
  // The normal direction is within a few degrees.
  const double angle_deg =
      AngleBetweenDeg(models[0], FacadeM());
  EXPECT_LT(angle_deg, 3.0);
}

TEST(EpipolarPlaneEstimatorTest, DegenerateInputGivesNoModel) {
  std::vector<Eigen::Vector3d> models;
  // Collinear later pixels.
  const Points line = {{100, 100}, {200, 200}, {300, 300}};
  Points earlier;
  for (const auto& x : line) earlier.push_back(x + Eigen::Vector2d(3, 1));
  EpipolarPlaneEstimator::Estimate(Prepare(line), earlier, &models);
  EXPECT_TRUE(models.empty());
  // Too few points, and mismatched sizes.
  EpipolarPlaneEstimator::Estimate(Prepare({line[0], line[1]}), {earlier[0], earlier[1]}, &models);
  EXPECT_TRUE(models.empty());
  EpipolarPlaneEstimator::Estimate(Prepare(line), {earlier[0]}, &models);
  EXPECT_TRUE(models.empty());
  // No translation: no epipolar information at all.
  const Points tri = {{100, 100}, {300, 120}, {200, 400}};
  EpipolarPlaneEstimator::Estimate(EpipolarPlaneEstimator::Prepare(tri, Camera(), Rigid3d()), tri,
                                   &models);
  EXPECT_TRUE(models.empty());
  // Least squares on points all on one line: rank deficient.
  Points many_line, many_earlier;
  for (int i = 0; i < 10; ++i) {
    many_line.push_back({50.0 + 20 * i, 60.0 + 10 * i});
    many_earlier.push_back(many_line.back() + Eigen::Vector2d(2, 1));
  }
  EpipolarPlaneEstimator::Estimate(Prepare(many_line), many_earlier, &models);
  EXPECT_TRUE(models.empty());
}

TEST(EpipolarPlaneEstimatorTest, RansacSeparatesTwoPlanesWithOutliers) {
  std::mt19937_64 rng(5);
  Points later, earlier;
  MakePlanePoints(FacadeM(), 400, 640, 0, 300, 0.25, rng, &later, &earlier);  // 15 x 19
  const size_t num_facade = later.size();
  MakePlanePoints(RoadM(), 0, 640, 320, 480, 0.25, rng, &later, &earlier);  // 40 x 10
  const size_t num_planes = later.size();
  std::uniform_real_distribution<double> off(-20, 20);
  for (int i = 0; i < 80; ++i) {  // wrong MVs
    later.push_back({off(rng) + 160, off(rng) + 150});
    earlier.push_back(later.back() + Eigen::Vector2d(off(rng), off(rng)));
  }
  RansacOptions options;
  options.max_error = 1.0;
  options.seed = 7;
  const auto report = Ransac<EpipolarPlaneEstimator>(options).Estimate(Prepare(later), earlier);
  ASSERT_TRUE(report.success);
  // The road (the larger plane) wins; its plane is recovered.
  int road_inliers = 0, facade_inliers = 0, outlier_inliers = 0;
  for (size_t i = 0; i < later.size(); ++i) {
    if (!report.inlier_mask[i]) continue;
    if (i < num_facade) {
      ++facade_inliers;
    } else if (i < num_planes) {
      ++road_inliers;
    } else {
      ++outlier_inliers;
    }
  }
  EXPECT_GE(road_inliers, static_cast<int>(0.95 * (num_planes - num_facade)));
  // Facade points near the facade-road intersection fit both planes.
  EXPECT_LE(facade_inliers, static_cast<int>(0.05 * num_facade));
  EXPECT_LE(outlier_inliers, 4);
  EXPECT_LT((report.model - RoadM()).norm(), 0.03 * RoadM().norm());
}

}  // namespace
}  // namespace slapse
