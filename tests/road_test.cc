// The one road test (core/common/road.h): one-sided, threshold in degrees,
// any length of normal or pi.
#include <algorithm>
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

// A level camera over a level road sees it at most half the vertical field of
// view below the horizon; pitching the camera down by p adds p; the value is
// the dense maximum over every pixel (within the sampling's error).
TEST(RoadTest, SteepestDepressionIsHalfTheVerticalFieldPlusThePitch) {
  const Intrinsics wide = Intrinsics::FromHorizontalFov(1242, 376, 86.6);
  const double half_vfov_deg = RadToDeg(std::atan((wide.height_px - 1 - wide.cy_px) / wide.fy_px));
  // Road 1.6 m below a level camera: pi = down / 1.6.
  EXPECT_NEAR(SteepestRoadDepressionDeg(Eigen::Vector3d(0, 1, 0) / 1.6, wide), half_vfov_deg, 1e-9);
  // Camera pitched 4 deg down: in the camera, the road's normal tilts back
  // towards the camera's forward axis.
  for (double pitch_deg : {-6.0, 4.0}) {
    const Eigen::Vector3d pi = TiltedDown(pitch_deg) / 2.0;
    const double steepest = SteepestRoadDepressionDeg(pi, wide);
    double dense = -1.0;
    for (int v = 0; v < wide.height_px; ++v) {
      for (int u = 0; u < wide.width_px; u += 3) {
        const Eigen::Vector3d ray = wide.Unproject({double(u), double(v)});
        dense = std::max(dense, pi.normalized().dot(ray.normalized()));
      }
    }
    EXPECT_NEAR(steepest, RadToDeg(std::asin(dense)), 0.05) << pitch_deg;
    // The bottom row's centre is the steepest ray when there is no roll.
    EXPECT_NEAR(steepest, half_vfov_deg + pitch_deg, 0.01) << pitch_deg;
  }
  // A 4:3 camera sees the road steeper than the wide one of the same hfov.
  const Intrinsics vga = Intrinsics::FromHorizontalFov(640, 480, 86.6);
  EXPECT_GT(SteepestRoadDepressionDeg(Eigen::Vector3d(0, 1, 0), vga), half_vfov_deg + 10);
}

// Looking straight down, the steepest ray is the normal (90 deg); a plane
// behind the camera is met by no ray (negative); a plane above (a ceiling)
// is met by the top rows, as steeply as a road by the bottom ones; a zero pi
// is no plane.
TEST(RoadTest, SteepestDepressionAtTheExtremes) {
  const Intrinsics cam = Intrinsics::FromHorizontalFov(640, 480, 60);
  EXPECT_DOUBLE_EQ(SteepestRoadDepressionDeg(Eigen::Vector3d(0, 0, 0.5), cam), 90.0);
  EXPECT_LT(SteepestRoadDepressionDeg(Eigen::Vector3d(0, 0, -0.5), cam), 0.0);
  EXPECT_NEAR(SteepestRoadDepressionDeg(Eigen::Vector3d(0, -1, 0), cam),
              SteepestRoadDepressionDeg(Eigen::Vector3d(0, 1, 0), cam), 1e-9);
  EXPECT_TRUE(std::isnan(SteepestRoadDepressionDeg(Eigen::Vector3d::Zero(), cam)));
}

}  // namespace
}  // namespace slapse
