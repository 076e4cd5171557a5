// The pair's motion (core/estimators/pair_motion.h) and the plane-at-infinity
// threshold given a motion (core/planes/infinity.h), on exact correspondences
// of random points 5-60 m ahead seen from two poses 1 m apart.
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "core/common/angles.h"
#include "core/estimators/pair_motion.h"
#include "core/planes/infinity.h"

namespace slapse {
namespace {

// 640x480, f = 457 px, pixel centres on integers.
Intrinsics TestIntrinsics() { return Intrinsics{457.0, 457.0, 319.5, 239.5, 640, 480}; }

AnchorPair PairOf(int64_t earlier_index, int64_t later_index) {
  AnchorPair pair;
  pair.earlier_index = earlier_index;
  pair.later_index = later_index;
  return pair;
}

// Correspondences of random points under later_from_earlier.
std::vector<Correspondence> Observe(const Rigid3d& later_from_earlier, int n) {
  const Intrinsics k = TestIntrinsics();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> x(-8, 8), y(-3, 2), z(5, 60);
  std::vector<Correspondence> out;
  while (static_cast<int>(out.size()) < n) {
    const Eigen::Vector3d X(x(rng), y(rng), z(rng));
    const Eigen::Vector3d Y = later_from_earlier * X;
    if (Y.z() < 1.0) continue;
    Correspondence c;
    c.x_earlier_px = k.Project(X);
    c.x_later_px = k.Project(Y);
    c.mb_index = static_cast<int>(out.size());
    out.push_back(c);
  }
  return out;
}

Rigid3d Forward() {
  return Rigid3d(Eigen::Matrix3d(Eigen::AngleAxisd(DegToRad(2.0), Eigen::Vector3d::UnitY())),
                 Eigen::Vector3d(0.05, 0.0, -1.0));
}

TEST(PairMotionTest, OptionsCheckNamesTheCaller) {
  PairMotionOptions o;
  EXPECT_TRUE(o.Check().ok());
  o.prior_decision_margin = 0.5;
  const Status s = o.Check("MyStage");
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("MyStage"), std::string::npos);
  o = PairMotionOptions();
  o.confidence = 1.0;
  EXPECT_FALSE(o.Check().ok());
}

TEST(PairMotionTest, TranslationIsObservedAndTheRotationKeptAsEstimated) {
  const std::vector<Correspondence> c = Observe(Forward(), 300);
  auto m = EstimatePairMotion(c, TestIntrinsics(), PairMotionOptions(), 6.0);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_TRUE(m->has_motion);
  EXPECT_EQ(m->rotation_source, PairRotationSource::kEssential);
  EXPECT_NEAR(Eigen::AngleAxisd(m->R_later_from_earlier.transpose() * Forward().R()).angle(), 0.0,
              1e-4);
  EXPECT_TRUE(m->R_later_from_earlier.isApprox(m->later_from_earlier.R(), 1e-12));
  EXPECT_NEAR(m->later_from_earlier.translation.norm(), 1.0, 1e-9);
}

// Without a prior the full path runs. Where E gives the motion, the
// rotation-only model is polished from E's rotation (no random search); it
// leaves as many points off it by the parallax threshold (6 px) as the true
// rotation does. Under a pure rotation the random search decides, as before,
// and its model is the pair's motion.
TEST(PairMotionTest, TheFullPathPolishesTheRotationOnlyModelFromEs) {
  const std::vector<Correspondence> c = Observe(Forward(), 300);
  auto m = EstimatePairMotion(c, TestIntrinsics(), PairMotionOptions(), 6.0);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_TRUE(m->full_fit);
  EXPECT_TRUE(m->has_motion);
  EXPECT_TRUE(m->rotation_only_from_essential);
  const Eigen::Matrix3d K = TestIntrinsics().K();
  const Eigen::Matrix3d KRKinv = K * Forward().R() * K.inverse();
  int off_true_rotation = 0;
  for (const Correspondence& ci : c) off_true_rotation += RotationOnlyParallaxPx(KRKinv, ci) >= 6.0;
  EXPECT_GT(off_true_rotation, 50);  // 76 of the 300
  EXPECT_NEAR(m->num_rotation_outliers, off_true_rotation, 0.05 * off_true_rotation);

  const Rigid3d turn(Eigen::Matrix3d(Eigen::AngleAxisd(DegToRad(3.0), Eigen::Vector3d::UnitY())),
                     Eigen::Vector3d::Zero());
  m = EstimatePairMotion(Observe(turn, 300), TestIntrinsics(), PairMotionOptions(), 6.0);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_FALSE(m->has_motion);
  EXPECT_FALSE(m->rotation_only_from_essential);
  EXPECT_EQ(m->rotation_source, PairRotationSource::kRotationOnly);
  EXPECT_NEAR(Eigen::AngleAxisd(m->R_later_from_earlier.transpose() * turn.R()).angle(), 0.0, 1e-4);
}

TEST(PairMotionTest, TooFewCorrespondencesEstimateNothing) {
  const std::vector<Correspondence> c = Observe(Forward(), 10);
  auto m = EstimatePairMotion(c, TestIntrinsics(), PairMotionOptions(), 6.0);
  ASSERT_TRUE(m.ok());
  EXPECT_FALSE(m->has_motion);
  EXPECT_EQ(m->rotation_source, PairRotationSource::kIdentity);
  EXPECT_EQ(m->R_later_from_earlier, Eigen::Matrix3d::Identity());
}

TEST(PairMotionTest, ThresholdInfinityIsTheMotionThenTheThreshold) {
  const std::vector<Correspondence> c = Observe(Forward(), 300);
  InfinityOptions options;
  auto combined = ThresholdInfinity(c, TestIntrinsics(), options);
  auto motion = EstimatePairMotion(c, TestIntrinsics(), options, options.tau_inf_px);
  ASSERT_TRUE(combined.ok() && motion.ok());
  const InfinityResult split = ThresholdInfinity(c, TestIntrinsics(), options.tau_inf_px, *motion);
  EXPECT_EQ(split.kept_indices, combined->kept_indices);
  EXPECT_EQ(split.dropped_indices, combined->dropped_indices);
  EXPECT_EQ(split.parallax_px, combined->parallax_px);
  EXPECT_FALSE(combined->kept_indices.empty());
  EXPECT_FALSE(combined->dropped_indices.empty());  // the far points
}

TEST(PairMotionTest, PriorTrackerSeedsOnlyConnectedPairs) {
  AnchorPair first = PairOf(0, 4), second = PairOf(4, 8), unrelated = PairOf(12, 16);
  first.correspondences = Observe(Forward(), 300);
  auto m = EstimatePairMotion(first.correspondences, TestIntrinsics(), PairMotionOptions(), 6.0);
  ASSERT_TRUE(m.ok() && m->has_motion);
  PairMotionPriorTracker tracker;
  EXPECT_EQ(tracker.PriorFor(first), nullptr);
  tracker.Record(first, &*m);
  ASSERT_NE(tracker.PriorFor(second), nullptr);
  EXPECT_NEAR(tracker.PriorFor(second)->reference_inlier_ratio,
              static_cast<double>(m->num_sampson_inliers) / 300, 1e-12);
  EXPECT_EQ(tracker.PriorFor(unrelated), nullptr);
  tracker.Record(second, nullptr);  // failed: no prior for what follows
  EXPECT_EQ(tracker.PriorFor(PairOf(8, 12)), nullptr);
}

}  // namespace
}  // namespace slapse
