// Generic RANSAC (sampling subset, determinism, adaptive trials) and the
// normalised-DLT homography estimator, on synthetic points with fixed seeds.
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/estimators/homography.h"
#include "core/estimators/ransac.h"

namespace slapse {
namespace {

using Points = std::vector<Eigen::Vector2d>;

Eigen::Matrix3d TrueHomography() {
  Eigen::Matrix3d H;
  H << 1.05, 0.04, -12.0,  //
      -0.03, 0.97, 8.0,    //
      6e-5, -4e-5, 1.0;
  return H;
}

Eigen::Matrix3d OtherHomography() {
  Eigen::Matrix3d H;
  H << 0.92, -0.06, 30.0,  //
      0.05, 1.1, -20.0,    //
      -1e-4, 2e-4, 1.0;
  return H;
}

Eigen::Vector2d Apply(const Eigen::Matrix3d& H, const Eigen::Vector2d& x) {
  return (H * x.homogeneous()).hnormalized();
}

Points RandomImagePoints(std::mt19937_64& rng, int n) {
  std::uniform_real_distribution<double> u(0.0, 640.0), v(0.0, 480.0);
  Points p(n);
  for (auto& x : p) x = {u(rng), v(rng)};
  return p;
}

// Largest transfer difference of two homographies over a grid on the image.
double MaxTransferDifferencePx(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B) {
  double worst = 0.0;
  for (double u = 0; u <= 640; u += 40) {
    for (double v = 0; v <= 480; v += 40) {
      worst = std::max(worst, (Apply(A, {u, v}) - Apply(B, {u, v})).norm());
    }
  }
  return worst;
}

TEST(RansacNumTrialsTest, MatchesFormulaAndClamps) {
  // log(0.001) / log(1 - 0.5^4) = 107.03 -> 108.
  EXPECT_EQ(internal::RansacNumTrials(0.5, 4, 0.999, 10, 2000), 108);
  EXPECT_EQ(internal::RansacNumTrials(1.0, 4, 0.999, 10, 2000), 10);
  EXPECT_EQ(internal::RansacNumTrials(0.0, 4, 0.999, 10, 2000), 2000);
  EXPECT_EQ(internal::RansacNumTrials(0.05, 4, 0.999, 10, 2000), 2000);
  EXPECT_EQ(internal::RansacNumTrials(0.99, 4, 0.999, 10, 2000), 10);
}

TEST(UniformIndexTest, CoversRangeUniformly) {
  std::mt19937_64 rng(7);
  std::vector<int> counts(7, 0);
  for (int i = 0; i < 70000; ++i) ++counts[internal::UniformIndex(rng, 7)];
  for (int c : counts) EXPECT_NEAR(c, 10000, 400);  // ~4 sigma
}

TEST(HomographyEstimatorTest, ExactMinimalAndLeastSquares) {
  std::mt19937_64 rng(1);
  const Eigen::Matrix3d H = TrueHomography();
  const Points x = RandomImagePoints(rng, 30);
  Points y;
  for (const auto& p : x) y.push_back(Apply(H, p));

  std::vector<Eigen::Matrix3d> models;
  const Points corners = {{20, 30}, {610, 15}, {600, 470}, {40, 440}};
  Points corners_y;
  for (const auto& p : corners) corners_y.push_back(Apply(H, p));
  HomographyEstimator::Estimate(corners, corners_y, &models);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_NEAR(models[0].norm(), 1.0, 1e-12);
  const Eigen::Matrix3d H_unit = H / H.norm();  // H(2,2) > 0 and w > 0 on the image: same sign
  EXPECT_LT((models[0] - H_unit).norm(), 1e-9);

  HomographyEstimator::Estimate(x, y, &models);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_LT((models[0] - H_unit).norm(), 1e-9);

  std::vector<double> residuals;
  HomographyEstimator::Residuals(x, y, models[0], &residuals);
  for (double r : residuals) EXPECT_LT(r, 1e-12);
}

TEST(HomographyEstimatorTest, ResidualIsSquaredTransferErrorAndInfiniteBehind) {
  const Eigen::Matrix3d H = TrueHomography();
  const Points x = {{100, 100}, {100, 100}, {-40000, 0}};
  const Points y = {Apply(H, {100, 100}), Apply(H, {100, 100}) + Eigen::Vector2d(3, 4), {0, 0}};
  // x = (-40000, 0): w = 6e-5 * -40000 + 1 = -1.4 < 0, i.e. behind.
  std::vector<double> r;
  HomographyEstimator::Residuals(x, y, H, &r);
  ASSERT_EQ(r.size(), 3u);
  EXPECT_NEAR(r[0], 0.0, 1e-18);
  EXPECT_NEAR(r[1], 25.0, 1e-9);
  EXPECT_EQ(r[2], std::numeric_limits<double>::infinity());
}

TEST(HomographyEstimatorTest, RejectsDegenerateSamples) {
  const Eigen::Matrix3d H = TrueHomography();
  std::vector<Eigen::Matrix3d> models;
  // Three collinear points in a minimal sample.
  Points x = {{0, 0}, {100, 50}, {200, 100}, {50, 300}};
  Points y;
  for (const auto& p : x) y.push_back(Apply(H, p));
  HomographyEstimator::Estimate(x, y, &models);
  EXPECT_TRUE(models.empty());

  // All of many points on one line (least-squares case): rank-deficient system.
  x.clear();
  y.clear();
  for (int i = 0; i < 20; ++i) {
    x.push_back({10.0 + 30 * i, 400.0 - 15 * i});
    y.push_back(Apply(H, x.back()));
  }
  HomographyEstimator::Estimate(x, y, &models);
  EXPECT_TRUE(models.empty());

  // Coincident points, too few points, size mismatch.
  HomographyEstimator::Estimate(Points(4, {5, 5}), Points(4, {7, 7}), &models);
  EXPECT_TRUE(models.empty());
  HomographyEstimator::Estimate({x.begin(), x.begin() + 3}, {y.begin(), y.begin() + 3}, &models);
  EXPECT_TRUE(models.empty());
  HomographyEstimator::Estimate({{0, 0}, {1, 0}, {0, 1}, {1, 1}}, {{0, 0}, {1, 0}, {0, 1}},
                                &models);
  EXPECT_TRUE(models.empty());

  // The four targets all on one line: only a singular H maps onto them.
  HomographyEstimator::Estimate({{0, 0}, {100, 0}, {0, 100}, {100, 100}},
                                {{0, 0}, {10, 10}, {20, 20}, {30, 30.5}}, &models);
  EXPECT_TRUE(models.empty());
}

TEST(HomographyEstimatorTest, RejectsNearlyCollinearMinimalSample) {
  // The third point is 0.5 px off a 200 px line (ratio 0.0025 < 1e-2): exact
  // data, a unique non-singular H exists, but with MV noise it would be junk.
  const Points x = {{0, 0}, {200, 0}, {100, 0.5}, {50, 150}};
  Points y;
  for (const auto& p : x) y.push_back(Apply(TrueHomography(), p));
  std::vector<Eigen::Matrix3d> models;
  HomographyEstimator::Estimate(x, y, &models);
  EXPECT_TRUE(models.empty());
  // 5 px off is a fine sample.
  const Points x_ok = {{0, 0}, {200, 0}, {100, 5.0}, {50, 150}};
  y.clear();
  for (const auto& p : x_ok) y.push_back(Apply(TrueHomography(), p));
  HomographyEstimator::Estimate(x_ok, y, &models);
  EXPECT_EQ(models.size(), 1u);
}

TEST(HomographyEstimatorTest, LeastSquaresSignMakesPointsFront) {
  // The DLT null vector has an arbitrary sign; the estimator must return the
  // one with w = (H x)_z > 0, else every residual would be "behind" (infinite).
  std::mt19937_64 rng(17);
  std::normal_distribution<double> noise(0.0, 0.3);
  for (int trial = 0; trial < 20; ++trial) {
    const Points x = RandomImagePoints(rng, 12 + trial);
    // A different homography each time: rotations by up to +-180 degrees
    // composed with the test homography.
    const double angle = (trial - 10) * 0.3;
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    R.topLeftCorner<2, 2>() = Eigen::Rotation2Dd(angle).toRotationMatrix();
    R.topRightCorner<2, 1>() =
        Eigen::Vector2d(320, 240) - R.topLeftCorner<2, 2>() * Eigen::Vector2d(320, 240);
    const Eigen::Matrix3d H = R * TrueHomography();
    Points y;
    for (const auto& p : x) y.push_back(Apply(H, p) + Eigen::Vector2d(noise(rng), noise(rng)));
    std::vector<Eigen::Matrix3d> models;
    HomographyEstimator::Estimate(x, y, &models);
    ASSERT_EQ(models.size(), 1u);
    std::vector<double> r;
    HomographyEstimator::Residuals(x, y, models[0], &r);
    for (double ri : r) EXPECT_LT(ri, 4.0) << "trial " << trial;
  }
}

TEST(HomographyEstimatorTest, LeastSquaresIsSimilarityInvariant) {
  // Hartley normalisation makes the DLT independent of the pixel units: fitting
  // points scaled by 1000 gives the conjugated homography S H S^-1.
  std::mt19937_64 rng(19);
  std::normal_distribution<double> noise(0.0, 0.5);
  const Points x = RandomImagePoints(rng, 40);
  Points y, x_big, y_big;
  const double k = 1000.0;
  for (const auto& p : x) {
    y.push_back(Apply(TrueHomography(), p) + Eigen::Vector2d(noise(rng), noise(rng)));
    x_big.push_back(k * p);
    y_big.push_back(k * y.back());
  }
  std::vector<Eigen::Matrix3d> small, big;
  HomographyEstimator::Estimate(x, y, &small);
  HomographyEstimator::Estimate(x_big, y_big, &big);
  ASSERT_EQ(small.size(), 1u);
  ASSERT_EQ(big.size(), 1u);
  const Eigen::Matrix3d S = Eigen::Vector3d(k, k, 1.0).asDiagonal();
  const Eigen::Matrix3d big_in_small_units = S.inverse() * big[0] * S;
  EXPECT_LT(MaxTransferDifferencePx(big_in_small_units, small[0]), 1e-6);
}

TEST(RansacHomographyTest, CollinearInputGivesNoModel) {
  Points x, y;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.3);
  for (int i = 0; i < 50; ++i) {
    x.push_back({7.5 + 16 * i, 103.5});  // one MB row
    y.push_back(x.back() + Eigen::Vector2d(2.0 + noise(rng), -1.0 + noise(rng)));
  }
  RansacOptions options;
  options.max_error = 1.0;
  const auto report = Ransac<HomographyEstimator>(options).Estimate(x, y);
  EXPECT_FALSE(report.success);
  EXPECT_TRUE(report.inlier_mask.empty());
  EXPECT_EQ(report.num_trials, options.max_num_trials);  // no hypothesis ever stopped it
}

TEST(RansacHomographyTest, ExactPointsRecoverH) {
  std::mt19937_64 rng(11);
  const Eigen::Matrix3d H = TrueHomography();
  const Points x = RandomImagePoints(rng, 100);
  Points y;
  for (const auto& p : x) y.push_back(Apply(H, p));
  RansacOptions options;
  options.max_error = 0.5;
  const auto report = Ransac<HomographyEstimator>(options).Estimate(x, y);
  ASSERT_TRUE(report.success);
  EXPECT_EQ(report.support, 100);
  EXPECT_EQ(report.num_trials, options.min_num_trials);  // all inliers: stops at the minimum
  EXPECT_LT((report.model - H / H.norm()).norm(), 1e-9);
}

// 60% inliers with 0.5 px noise per axis, 40% uniformly random y.
struct NoisyProblem {
  Points x, y;
  std::vector<char> is_inlier;
};

NoisyProblem MakeNoisyProblem(uint64_t seed, int n, double outlier_ratio) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.5);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  NoisyProblem p;
  p.x = RandomImagePoints(rng, n);
  const Points garbage = RandomImagePoints(rng, n);
  for (int i = 0; i < n; ++i) {
    const bool inlier = unit(rng) >= outlier_ratio;
    p.is_inlier.push_back(inlier);
    p.y.push_back(inlier ? Apply(TrueHomography(), p.x[i]) + Eigen::Vector2d(noise(rng), noise(rng))
                         : garbage[i]);
  }
  return p;
}

TEST(RansacHomographyTest, NoisyPointsWithFortyPercentOutliers) {
  const NoisyProblem p = MakeNoisyProblem(/*seed=*/5, 300, 0.4);
  RansacOptions options;
  options.max_error = 2.0;  // 4 sigma
  options.seed = 42;
  const auto report = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  ASSERT_TRUE(report.success);
  int true_pos = 0, false_pos = 0, num_inliers = 0;
  for (size_t i = 0; i < p.x.size(); ++i) {
    num_inliers += p.is_inlier[i];
    if (report.inlier_mask[i]) (p.is_inlier[i] ? true_pos : false_pos)++;
  }
  EXPECT_GE(true_pos, 0.98 * num_inliers);
  EXPECT_LE(false_pos, 3);  // a random point lands within 2 px by chance rarely
  EXPECT_LT(report.num_trials, options.max_num_trials);  // adaptive stop
  EXPECT_LT(MaxTransferDifferencePx(report.model, TrueHomography()),
            0.75);  // 1.5 sigma, whole image
}

TEST(RansacHomographyTest, LocalOptimizationDoesNotHurt) {
  const NoisyProblem p = MakeNoisyProblem(/*seed=*/9, 300, 0.4);
  RansacOptions options;
  options.max_error = 2.0;
  options.local_optimization = false;
  const auto plain = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  options.local_optimization = true;
  const auto lo = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  ASSERT_TRUE(plain.success && lo.success);
  // The refit may trade a borderline inlier for a lower MSAC cost, no more.
  EXPECT_GE(lo.support, plain.support - 3);
  // A least-squares fit on ~180 inliers beats a 4-point model with 0.5 px noise.
  EXPECT_LT(MaxTransferDifferencePx(lo.model, TrueHomography()),
            MaxTransferDifferencePx(plain.model, TrueHomography()));
  EXPECT_LT(MaxTransferDifferencePx(lo.model, TrueHomography()), 0.75);
}

TEST(RansacHomographyTest, DeterministicGivenSeed) {
  const NoisyProblem p = MakeNoisyProblem(/*seed=*/13, 200, 0.4);
  RansacOptions options;
  options.max_error = 2.0;
  options.seed = 123;
  const auto a = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  const auto b = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  ASSERT_TRUE(a.success);
  EXPECT_EQ(a.num_trials, b.num_trials);
  EXPECT_EQ(a.support, b.support);
  EXPECT_EQ(a.inlier_mask, b.inlier_mask);
  EXPECT_EQ(a.model, b.model);  // bitwise
  // With local optimisation off, the model is one minimal sample's: a different
  // seed draws a different sequence of samples.
  options.local_optimization = false;
  const auto c = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  options.seed = 124;
  const auto d = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  ASSERT_TRUE(c.success && d.success);
  EXPECT_NE(c.model, d.model);
}

// Two planes: 150 points on H1 (the larger), 90 on H2, 60 random.
struct TwoPlanes {
  Points x, y;
  std::vector<int> label;  // 1, 2, or 0 for outliers
  std::vector<int> indices_of[3];
};

TwoPlanes MakeTwoPlanes() {
  std::mt19937_64 rng(21);
  std::normal_distribution<double> noise(0.0, 0.25);
  TwoPlanes t;
  const Points x = RandomImagePoints(rng, 300);
  const Points garbage = RandomImagePoints(rng, 300);
  for (int i = 0; i < 300; ++i) {
    const int label = i < 150 ? 1 : (i < 240 ? 2 : 0);
    const Eigen::Vector2d n(noise(rng), noise(rng));
    t.x.push_back(x[i]);
    t.y.push_back(label == 1   ? Apply(TrueHomography(), x[i]) + n
                  : label == 2 ? Apply(OtherHomography(), x[i]) + n
                               : garbage[i]);
    t.label.push_back(label);
    t.indices_of[label].push_back(i);
  }
  return t;
}

TEST(RansacSampleSubsetTest, SubsetRestrictsSamplingButScoresAll) {
  const TwoPlanes t = MakeTwoPlanes();
  RansacOptions options;
  options.max_error = 1.0;
  const Ransac<HomographyEstimator> ransac(options);

  const auto all = ransac.Estimate(t.x, t.y);
  ASSERT_TRUE(all.success);
  EXPECT_LT(MaxTransferDifferencePx(all.model, TrueHomography()), 0.5);  // the larger plane

  // Sampling only from plane 2's points finds plane 2 ...
  const auto sub = ransac.Estimate(t.x, t.y, &t.indices_of[2]);
  ASSERT_TRUE(sub.success);
  EXPECT_LT(MaxTransferDifferencePx(sub.model, OtherHomography()), 0.5);
  int on_2 = 0;
  for (int i : t.indices_of[2]) on_2 += sub.inlier_mask[i];
  EXPECT_GE(on_2, 85);
  // ... and scores all points: a subset of 10 of them still yields (nearly) all 90.
  const std::vector<int> few(t.indices_of[2].begin(), t.indices_of[2].begin() + 10);
  const auto few_report = ransac.Estimate(t.x, t.y, &few);
  ASSERT_TRUE(few_report.success);
  EXPECT_GE(few_report.support, 85);
  int on_1 = 0;  // plane-1 points where the two homographies happen to agree
  for (int i : t.indices_of[1]) on_1 += few_report.inlier_mask[i];
  EXPECT_LE(on_1, 3);

  // Duplicates in the subset are harmless.
  std::vector<int> dup = few;
  dup.insert(dup.end(), few.begin(), few.end());
  EXPECT_TRUE(ransac.Estimate(t.x, t.y, &dup).success);
}

TEST(RansacSampleSubsetTest, EmptyTooSmallOrInvalidSubsetGivesNoModel) {
  const TwoPlanes t = MakeTwoPlanes();
  RansacOptions options;
  options.max_error = 1.0;
  const Ransac<HomographyEstimator> ransac(options);
  const std::vector<int> empty, three = {0, 1, 2}, bad = {0, 1, 2, 3, 300}, neg = {0, 1, 2, -1};
  EXPECT_FALSE(ransac.Estimate(t.x, t.y, &empty).success);
  EXPECT_FALSE(ransac.Estimate(t.x, t.y, &three).success);
  EXPECT_FALSE(ransac.Estimate(t.x, t.y, &bad).success);
  EXPECT_FALSE(ransac.Estimate(t.x, t.y, &neg).success);
  // Four distinct points are enough to sample from: plane-2 points nearest to
  // the image corners (a well-conditioned sample).
  std::vector<int> four;
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(0, 0), Eigen::Vector2d(640, 0),
                                        Eigen::Vector2d(640, 480), Eigen::Vector2d(0, 480)}) {
    int nearest = t.indices_of[2][0];
    for (int i : t.indices_of[2]) {
      if ((t.x[i] - corner).norm() < (t.x[nearest] - corner).norm()) nearest = i;
    }
    four.push_back(nearest);
  }
  EXPECT_TRUE(ransac.Estimate(t.x, t.y, &four).success);
}

// Polish: no random search; a perturbed model (say, the previous frame's) is
// refitted onto the inliers, the best of several wins, and a model explaining
// nothing fails.
TEST(RansacPolishTest, PolishesTheBestOfGivenModels) {
  const NoisyProblem p = MakeNoisyProblem(/*seed=*/17, 300, 0.4);
  RansacOptions options;
  options.max_error = 2.0;
  const auto full = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  ASSERT_TRUE(full.success);
  Eigen::Matrix3d off = TrueHomography();
  off(0, 2) += 3.0;  // 3 px sideways
  const Eigen::Matrix3d far = Eigen::Vector3d(1, 2, 3).asDiagonal();
  const auto polished = Ransac<HomographyEstimator>(options).Polish(p.x, p.y, {far, off});
  ASSERT_TRUE(polished.success);
  EXPECT_EQ(polished.num_trials, 0);
  EXPECT_GE(polished.support, full.support - 3);
  EXPECT_LT(MaxTransferDifferencePx(polished.model, TrueHomography()), 0.75);
  EXPECT_FALSE(Ransac<HomographyEstimator>(options).Polish(p.x, p.y, {far}).success);
  EXPECT_FALSE(Ransac<HomographyEstimator>(options).Polish(p.x, p.y, {}).success);
}

// Local sampling: one compact plane (20 % of the points, in the image's left
// quarter) among garbage. Samples from neighbourhoods are all-inlier far more
// often, so the adaptive trial count is a fraction of the uniform one.
TEST(RansacLocalSamplingTest, FindsACompactPlaneWithFewerTrials) {
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> left_u(0, 160), any_u(160, 640), any_v(0, 480);
  std::normal_distribution<double> noise(0.0, 0.25);
  Points x, y;
  std::vector<char> on_plane;
  for (int i = 0; i < 300; ++i) {
    const bool plane = i % 5 == 0;
    const Eigen::Vector2d p(plane ? left_u(rng) : any_u(rng), any_v(rng));
    x.push_back(p);
    y.push_back(plane ? Eigen::Vector2d(Apply(TrueHomography(), p) +
                                        Eigen::Vector2d(noise(rng), noise(rng)))
                      : Eigen::Vector2d(any_u(rng), any_v(rng)));
    on_plane.push_back(plane);
  }
  std::vector<std::vector<int>> neighbours(x.size());
  for (size_t i = 0; i < x.size(); ++i) {
    for (size_t j = 0; j < x.size(); ++j) {
      if (j != i && (x[i] - x[j]).norm() < 80.0) neighbours[i].push_back(static_cast<int>(j));
    }
  }
  RansacOptions options;
  options.max_error = 1.0;
  options.seed = 3;
  const Ransac<HomographyEstimator> ransac(options);
  const auto uniform = ransac.Estimate(x, y);
  const auto local = ransac.Estimate(x, y, nullptr, &neighbours);
  ASSERT_TRUE(uniform.success && local.success);
  int found = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    if (!on_plane[i]) continue;
    found += local.inlier_mask[i];
    // Where the plane is seen (a free homography extrapolates poorly beyond).
    EXPECT_LT((Apply(local.model, x[i]) - Apply(TrueHomography(), x[i])).norm(), 0.5);
  }
  EXPECT_GE(found, 55);
  EXPECT_LT(local.num_trials, uniform.num_trials / 4);
  // Deterministic.
  const auto again = ransac.Estimate(x, y, nullptr, &neighbours);
  EXPECT_EQ(again.inlier_mask, local.inlier_mask);
  EXPECT_EQ(again.num_trials, local.num_trials);
  // One list per point, or no model.
  neighbours.pop_back();
  EXPECT_FALSE(ransac.Estimate(x, y, nullptr, &neighbours).success);
}

// The pre-test skips full scoring of poor hypotheses; the result is as good.
TEST(RansacPretestTest, SameQualityAsFullScoring) {
  const NoisyProblem p = MakeNoisyProblem(/*seed=*/23, 400, 0.6);
  RansacOptions options;
  options.max_error = 2.0;
  options.seed = 5;
  const auto full = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  options.pretest_points = 100;
  const auto pretested = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  ASSERT_TRUE(full.success && pretested.success);
  EXPECT_GE(pretested.support, full.support - 3);
  EXPECT_LT(MaxTransferDifferencePx(pretested.model, TrueHomography()), 0.75);
  const auto again = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  EXPECT_EQ(again.inlier_mask, pretested.inlier_mask);
  // Too few points for the test set: off, the same as full scoring.
  options.pretest_points = 201;
  const auto off = Ransac<HomographyEstimator>(options).Estimate(p.x, p.y);
  EXPECT_EQ(off.inlier_mask, full.inlier_mask);
  EXPECT_EQ(off.num_trials, full.num_trials);
}

TEST(RansacTest, RejectsBrokenInput) {
  const TwoPlanes t = MakeTwoPlanes();
  RansacOptions options;  // max_error = 0: invalid
  EXPECT_FALSE(Ransac<HomographyEstimator>(options).Estimate(t.x, t.y).success);
  options.max_error = 1.0;
  Points y_short(t.y.begin(), t.y.end() - 1);
  EXPECT_FALSE(Ransac<HomographyEstimator>(options).Estimate(t.x, y_short).success);
  EXPECT_FALSE(Ransac<HomographyEstimator>(options).Estimate({}, {}).success);
}

}  // namespace
}  // namespace slapse
