// ScaleSupport (core/pipeline/frame_poses.h): the share of anchor steps a
// plane measured, and the verdict `run`, the evaluation and the service give.
#include <string>

#include <gtest/gtest.h>

#include "core/pipeline/frame_poses.h"

namespace slapse {
namespace {

TEST(ScaleSupportTest, CountsOnlyPlaneMeasuredStepsAsHeld) {
  ScaleSupport s;
  EXPECT_EQ(s.PlaneStepShare(), 0.0);
  EXPECT_FALSE(s.Weak());  // no step: nothing to judge
  EXPECT_EQ(s.Summary(), "no anchor step tracked");
  for (int i = 0; i < 7; ++i) s.Count(PoseKind::kAnchor);
  s.Count(PoseKind::kCoasting);
  s.Count(PoseKind::kMotionOnly);
  s.Count(PoseKind::kMotionOnly);
  EXPECT_EQ(s.anchor_steps, 10);
  EXPECT_EQ(s.plane_steps, 7);
  EXPECT_DOUBLE_EQ(s.PlaneStepShare(), 0.7);
  EXPECT_FALSE(s.Weak());  // 70 % is the bound, inclusive
  EXPECT_EQ(s.Summary(), "planes measured 70 % of the 10 anchor steps");
}

// A MOTION_ONLY or COASTING step whose length the road in the B frames
// measured counts as measured, and the summary says how many those were; an
// ANCHOR step with it is measured once.
TEST(ScaleSupportTest, StepsTheRoadInTheFramesMeasuredAreHeld) {
  ScaleSupport s;
  s.Count(PoseKind::kAnchor, true);
  s.Count(PoseKind::kAnchor);
  s.Count(PoseKind::kMotionOnly, true);
  s.Count(PoseKind::kCoasting, true);
  s.Count(PoseKind::kMotionOnly);
  EXPECT_EQ(s.anchor_steps, 5);
  EXPECT_EQ(s.plane_steps, 4);
  EXPECT_EQ(s.road_frame_steps, 2);
  EXPECT_FALSE(s.Weak());
  EXPECT_EQ(s.Summary(),
            "planes measured 80 % of the 5 anchor steps (2 of them the road in the B frames next "
            "to the earlier anchor)");
}

TEST(ScaleSupportTest, AWeakShareSaysTheScaleFollowsTheMotionModel) {
  ScaleSupport s;
  s.Count(PoseKind::kAnchor);
  for (int i = 0; i < 3; ++i) s.Count(PoseKind::kMotionOnly);
  EXPECT_TRUE(s.Weak());
  const std::string text = s.Summary();
  EXPECT_EQ(text.rfind("planes measured 25 % of the 4 anchor steps: ", 0), 0u) << text;
  EXPECT_NE(text.find("motion model"), std::string::npos) << text;
  EXPECT_NE(text.find("Scale support"), std::string::npos) << text;  // where it is explained
}

}  // namespace
}  // namespace slapse
