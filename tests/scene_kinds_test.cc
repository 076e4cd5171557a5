// The widened simulator (issue 12): every scene kind makes valid geometry and
// ground truth (planes in gt whose polygons lie on them, the camera above the
// road, a path as long as its speeds say), kinds look like what they claim
// (no facades on a rural road, rails on the highway, cars on the lot, 90-degree
// turns at intersections), the look varies with the seed without moving the
// geometry, and the yardstick's drive table is fixed and covers everything.
#include <cmath>
#include <set>
#include <string>

#include <gtest/gtest.h>

#include "lab/eval/drive_table.h"
#include "lab/gt/ground_truth.h"
#include "lab/sim/renderer.h"
#include "lab/sim/scene.h"
#include "lab/sim/simulate.h"

namespace slapse {
namespace {

SimulateOptions SmallDrive(SceneKind kind, uint64_t seed) {
  SimulateOptions o;
  o.seed = seed;
  o.scene_kind = kind;
  o.appearance_variety = true;
  o.duration_s = 6.0;
  o.fps = 10.0;
  o.width_px = 160;
  o.height_px = 120;
  const DriveSpec spec = MakeDriveSpec(kind, 1);
  o.min_speed_mps = spec.sim.min_speed_mps;
  o.max_speed_mps = spec.sim.max_speed_mps;
  o.camera_height_min_m = 1.2;
  o.camera_height_max_m = 2.5;
  o.pitch_down_min_deg = -5.0;
  o.pitch_down_max_deg = 10.0;
  return o;
}

int CountKind(const Scene& sc, PlaneKind kind) {
  int n = 0;
  for (const GtPlane& p : sc.planes) n += p.kind == kind;
  return n;
}

// Smallest |lateral - lateral_ref| of a plane's polygon vertices whose
// centreline station lies in [s0, s1].
double MinLateral(const Scene& sc, const GtPlane& p, double lateral_ref = 0.0, double s0 = -1e300,
                  double s1 = 1e300) {
  double best = 1e300;
  for (const auto& poly : p.polygons_world) {
    for (const auto& x : poly) {
      double s = 0, l = 0;
      sc.centreline.Project(x.head<2>(), &s, &l);
      if (s >= s0 && s <= s1) best = std::min(best, std::abs(l - lateral_ref));
    }
  }
  return best;
}

class SceneKindTest : public ::testing::TestWithParam<SceneKind> {};

TEST_P(SceneKindTest, ValidGeometryAndGroundTruth) {
  const SceneKind kind = GetParam();
  for (uint64_t seed : {11u, 12u}) {
    const SimulateOptions o = SmallDrive(kind, seed);
    auto drive = PrepareDrive(o);
    ASSERT_TRUE(drive.ok()) << SceneKindName(kind) << ": " << drive.status().ToString();
    const Scene& sc = drive->scene;
    EXPECT_EQ(sc.kind, kind);
    // Plane 0 is the road z = 0; every plane has a unit normal and its polygons lie on it.
    ASSERT_FALSE(sc.planes.empty());
    EXPECT_EQ(sc.planes[0].kind, PlaneKind::kRoad);
    EXPECT_EQ(sc.planes[0].normal_world, Eigen::Vector3d::UnitZ());
    EXPECT_EQ(sc.planes[0].distance_m, 0.0);
    for (size_t i = 0; i < sc.planes.size(); ++i) {
      const GtPlane& p = sc.planes[i];
      ASSERT_EQ(p.id, static_cast<int>(i));
      EXPECT_NEAR(p.normal_world.norm(), 1.0, 1e-12);
      ASSERT_FALSE(p.polygons_world.empty()) << "plane " << i;
      for (const auto& poly : p.polygons_world) {
        ASSERT_GE(poly.size(), 3u);
        for (const auto& x : poly) {
          ASSERT_NEAR(p.normal_world.dot(x), p.distance_m, 1e-6) << "plane " << i;
        }
      }
    }
    // Surfaces: every textured surface refers to a texture, labels to planes or clutter.
    for (const Surface& s : sc.surfaces) {
      ASSERT_GE(s.texture, 0);
      ASSERT_LT(s.texture, static_cast<int>(sc.textures.size()));
      ASSERT_TRUE(s.label == kMbClutter || (s.label >= 0 && s.label < (int)sc.planes.size()));
    }
    // The camera: above the road at the drawn height, inside the road's strip, and
    // the path as long as its speeds say (trapezoid over the frames).
    const CameraPath& path = drive->path;
    ASSERT_EQ(path.world_from_cam.size(), 60u);
    EXPECT_GE(path.camera_height_m, 1.2);
    EXPECT_LE(path.camera_height_m, 2.5);
    EXPECT_GE(path.pitch_down_deg, -5.0);
    EXPECT_LE(path.pitch_down_deg, 10.0);
    double from_speed = 0.0;
    for (size_t i = 0; i < path.world_from_cam.size(); ++i) {
      const Eigen::Vector3d& c = path.world_from_cam[i].translation;
      // The drawn height plus the suspension's bounce (SimulateOptions::bounce_m).
      EXPECT_NEAR(c.z(), path.camera_height_m, o.bounce_m + 1e-12);
      double s = 0, l = 0;
      sc.centreline.Project(c.head<2>(), &s, &l);
      EXPECT_LT(std::abs(l), sc.road.half_width_m) << "frame " << i << " off the asphalt";
      EXPECT_GE(path.speed_mps[i], o.min_speed_mps - 1e-9);
      EXPECT_LE(path.speed_mps[i], o.max_speed_mps + 1e-9);
      if (i > 0) from_speed += 0.5 * (path.speed_mps[i] + path.speed_mps[i - 1]) / o.fps;
    }
    EXPECT_NEAR(path.distance_m, from_speed, 0.02 * from_speed);
    // Nothing but the road within 1 m of the camera's lane (nothing to drive through).
    for (const GtPlane& p : sc.planes) {
      if (p.kind == PlaneKind::kRoad || p.kind == PlaneKind::kBackground) continue;
      EXPECT_GT(MinLateral(sc, p, sc.lane_offset_m, path.s_m.front() - 10, path.s_m.back() + 10),
                1.0)
          << PlaneKindName(p.kind) << " plane " << p.id << " on the lane";
    }
  }
}

TEST_P(SceneKindTest, RendersRoadBelowAndSkyOrSceneAbove) {
  const SceneKind kind = GetParam();
  SimulateOptions o = SmallDrive(kind, 21);
  o.pitch_down_min_deg = o.pitch_down_max_deg = 3.0;
  auto drive = PrepareDrive(o);
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  RenderOptions ro;
  ro.supersampling = 1;
  auto frame = RenderFrame(drive->scene, drive->intrinsics, drive->path.world_from_cam[5], ro);
  ASSERT_TRUE(frame.ok()) << frame.status().ToString();
  // The bottom-centre macroblock sees the road.
  const int bottom = (frame->mb_rows - 1) * frame->mb_cols + frame->mb_cols / 2;
  EXPECT_EQ(frame->mb_labels[bottom], 0) << SceneKindName(kind);
  // The picture has texture (not a flat fill).
  cv::Scalar mean, stddev;
  cv::meanStdDev(frame->bgr, mean, stddev);
  EXPECT_GT(stddev[0] + stddev[1] + stddev[2], 15.0);
}

INSTANTIATE_TEST_SUITE_P(AllKinds, SceneKindTest,
                         ::testing::Values(SceneKind::kUrban, SceneKind::kAvenue, SceneKind::kRural,
                                           SceneKind::kHighway, SceneKind::kPlaza,
                                           SceneKind::kIntersection),
                         [](const auto& info) { return std::string(SceneKindName(info.param)); });

TEST(SceneKindsTest, KindsHaveTheirParts) {
  auto make = [](SceneKind kind) {
    SceneOptions o = SceneOptionsFor(kind);
    o.seed = 5;
    o.length_m = 300.0;
    auto sc = GenerateStreetScene(o);
    EXPECT_TRUE(sc.ok()) << sc.status().ToString();
    return std::move(sc).value();
  };
  const Scene urban = make(SceneKind::kUrban), avenue = make(SceneKind::kAvenue),
              rural = make(SceneKind::kRural), highway = make(SceneKind::kHighway),
              plaza = make(SceneKind::kPlaza), corner = make(SceneKind::kIntersection);
  auto clutter = [](const Scene& sc) {
    int n = 0;
    for (const Surface& s : sc.surfaces) n += s.label == kMbClutter;
    return n;
  };
  // Rural road and highway: no buildings; rails (planes) and trees (clutter).
  EXPECT_EQ(CountKind(rural, PlaneKind::kFacade), 0);
  EXPECT_EQ(CountKind(highway, PlaneKind::kFacade), 0);
  EXPECT_GT(CountKind(highway, PlaneKind::kGuardRail), 20);
  EXPECT_GT(CountKind(rural, PlaneKind::kGuardRail), 0);
  EXPECT_GT(clutter(rural), 1000);
  EXPECT_EQ(rural.road.verge, RoadStyle::Verge::kField);
  // Rails are narrow strips 0.45-0.75 m above the ground.
  for (const GtPlane& p : highway.planes) {
    if (p.kind != PlaneKind::kGuardRail) continue;
    for (const auto& x : p.polygons_world[0]) {
      EXPECT_TRUE(std::abs(x.z() - 0.45) < 1e-12 || std::abs(x.z() - 0.75) < 1e-12);
    }
  }
  // Avenue: facades further than 13 m, many trees; urban: facades within 13 m.
  for (const GtPlane& p : avenue.planes) {
    if (p.kind == PlaneKind::kFacade) {
      EXPECT_GT(MinLateral(avenue, p), 13.0);
    }
  }
  EXPECT_GT(clutter(avenue), 2 * clutter(urban));
  // Plaza: parked cars (object planes), facades 30 m away or more.
  EXPECT_GT(CountKind(plaza, PlaneKind::kObject), 50);
  for (const GtPlane& p : plaza.planes) {
    if (p.kind == PlaneKind::kFacade) {
      EXPECT_GT(MinLateral(plaza, p), 30.0);
    }
  }
  // Intersection: the centreline turns by 90 degrees at each bend.
  int corners = 0;
  for (const auto& seg : corner.centreline.segments()) {
    if (seg.curvature == 0.0) continue;
    EXPECT_NEAR(std::abs(seg.curvature) * seg.length_m, M_PI / 2, 1e-9);
    ++corners;
  }
  EXPECT_GE(corners, 3);
}

TEST(SceneKindsTest, AppearanceVariesWithTheSeedNotTheGeometry) {
  SceneOptions plain = SceneOptionsFor(SceneKind::kRural), varied = plain;
  plain.seed = varied.seed = 9;
  varied.appearance_variety = true;
  auto a = GenerateStreetScene(plain);
  auto b = GenerateStreetScene(varied);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->planes.size(), b->planes.size());
  for (size_t i = 0; i < a->planes.size(); ++i) {
    EXPECT_EQ(a->planes[i].normal_world, b->planes[i].normal_world);
    EXPECT_EQ(a->planes[i].distance_m, b->planes[i].distance_m);
  }
  EXPECT_EQ(a->surfaces.size(), b->surfaces.size());
  // Two seeds: different light, sky and road.
  varied.seed = 10;
  auto c = GenerateStreetScene(varied);
  ASSERT_TRUE(c.ok());
  EXPECT_NE(b->lighting.exposure, c->lighting.exposure);
  EXPECT_NE(b->road.asphalt_bgr, c->road.asphalt_bgr);
  EXPECT_NE(b->road.grain, c->road.grain);
  // Without variety, the urban street is today's (defaults untouched).
  EXPECT_EQ(a->lighting.exposure, 1.0f);
  EXPECT_EQ(a->road.asphalt_bgr, cv::Vec3f(84, 86, 88));
}

TEST(DriveTableTest, FixedSplitCoveringEveryKindRateAndSize) {
  const std::vector<DriveSpec> table = DriveTable();
  ASSERT_EQ(table.size(), 48u);
  std::set<std::string> names;
  for (DriveSplit split : {DriveSplit::kTuning, DriveSplit::kReporting}) {
    std::set<int> kinds;
    std::set<double> fps;
    std::set<int> widths;
    int n = 0;
    for (const DriveSpec& d : table) {
      names.insert(d.name);
      EXPECT_EQ(d.split, d.seed % 2 == 1 ? DriveSplit::kTuning : DriveSplit::kReporting);
      if (d.split != split) continue;
      ++n;
      kinds.insert(static_cast<int>(d.kind));
      fps.insert(d.sim.fps);
      widths.insert(d.sim.width_px);
      EXPECT_GE(d.sim.camera_height_min_m, 1.2);
      EXPECT_LE(d.sim.camera_height_max_m, 2.5);
      EXPECT_GE(-d.sim.pitch_down_min_deg, -10.0);  // pitch up positive in -10..5
      EXPECT_LE(-d.sim.pitch_down_min_deg, 5.0);
      EXPECT_GE(d.sim.min_speed_mps * 3.6, 10.0 - 1e-9);
      EXPECT_LE(d.sim.max_speed_mps * 3.6, 100.0 + 1e-9);
      EXPECT_GE(d.sim.bounce_m, 0.005);  // every drive's camera bounces, by up to 3 cm
      EXPECT_LE(d.sim.bounce_m, 0.03);
      EXPECT_TRUE(d.sim.appearance_variety);
    }
    EXPECT_EQ(n, 24);
    EXPECT_EQ(kinds.size(), static_cast<size_t>(kNumSceneKinds));
    EXPECT_EQ(fps, (std::set<double>{10, 25, 30, 60}));
    EXPECT_EQ(widths, (std::set<int>{640, 1280, 1242}));
  }
  EXPECT_EQ(names.size(), 48u);
  // Deterministic and parseable by name.
  auto again = ParseDriveName("highway-6");
  ASSERT_TRUE(again.ok());
  const DriveSpec& listed = table[3 * 8 + 5];
  EXPECT_EQ(listed.name, "highway-6");
  EXPECT_EQ(again->sim.seed, listed.sim.seed);
  EXPECT_EQ(again->sim.hfov_deg, listed.sim.hfov_deg);
  EXPECT_EQ(again->sim.camera_height_min_m, listed.sim.camera_height_min_m);
  EXPECT_FALSE(ParseDriveName("forest-1").ok());
  EXPECT_FALSE(ParseDriveName("rural-0").ok());
  EXPECT_FALSE(ParseDriveName("rural").ok());
  EXPECT_TRUE(EncoderProfile("h264-ippp").ok());
  EXPECT_EQ(EncoderProfile("h264-ippp")->b_frames, 0);
  // Camera-like presets are profiles too, their GOP in seconds of the drive.
  ASSERT_TRUE(EncoderProfile("h264-baseline-ippp-2s", 25.0).ok());
  EXPECT_EQ(EncoderProfile("h264-baseline-ippp-2s", 25.0)->gop_size, 50);
  EXPECT_EQ(EncoderProfile("h264-baseline-ippp-2s", 10.0)->gop_size, 20);
  EXPECT_EQ(EncoderProfile("hevc", 30.0)->codec, VideoCodec::kHevc);
  EXPECT_FALSE(EncoderProfile("h265-ippp").ok());
  EXPECT_FALSE(EncoderProfile("h264-baseline-ippp-2s", 0.0).ok());
}

}  // namespace
}  // namespace slapse
