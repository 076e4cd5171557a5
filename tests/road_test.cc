// The one road test (core/common/road.h): one-sided, threshold in degrees,
// any length of normal or pi.
#include <cmath>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "core/common/angles.h"
#include "core/common/road.h"

namespace slapse {
namespace {

// A unit normal tilted by `deg` from +y about the x axis.
Eigen::Vector3d TiltedDown(double deg) {
  return Eigen::AngleAxisd(DegToRad(deg), Eigen::Vector3d::UnitX()) * Eigen::Vector3d::UnitY();
}

TEST(RoadTest, NormalWithinTheAngleOfDownIsTheRoad) {
  EXPECT_TRUE(IsRoadLike(CameraDown(), CameraDown(), 20.0));
  EXPECT_TRUE(IsRoadLike(TiltedDown(19.0), CameraDown(), 20.0));
  EXPECT_FALSE(IsRoadLike(TiltedDown(21.0), CameraDown(), 20.0));
  EXPECT_TRUE(IsRoadLike(TiltedDown(21.0), CameraDown(), 25.0));
  // A wall is no road at any sensible threshold.
  EXPECT_FALSE(IsRoadLike(Eigen::Vector3d::UnitX(), CameraDown(), 45.0));
}

TEST(RoadTest, OneSidedACeilingIsNoRoad) {
  EXPECT_FALSE(IsRoadLike(-CameraDown(), CameraDown(), 20.0));
  EXPECT_FALSE(IsRoadLike(-TiltedDown(5.0), CameraDown(), 20.0));
  EXPECT_LT(DownComponent(-CameraDown(), CameraDown()), 0.0);
}

TEST(RoadTest, PiOfAnyLengthAndAnyDownDirection) {
  // pi = n / d for a road 1.5 m below: the same answer as its unit normal.
  const Eigen::Vector3d pi = TiltedDown(10.0) / 1.5;
  EXPECT_TRUE(IsRoadLike(pi, CameraDown(), 15.0));
  EXPECT_NEAR(DownComponent(pi, CameraDown()), std::cos(DegToRad(10.0)), 1e-12);
  // Against a learnt vertical pitched by 10 deg the same plane is level.
  EXPECT_NEAR(DownComponent(pi, TiltedDown(10.0)), 1.0, 1e-12);
  EXPECT_TRUE(IsRoadLike(pi, TiltedDown(10.0), 1.0));
  EXPECT_FALSE(IsRoadLike(Eigen::Vector3d::Zero(), CameraDown(), 90.0));
}

}  // namespace
}  // namespace slapse
