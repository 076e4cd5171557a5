// Today's pipeline on every scene kind of the widened simulator, end to end:
// a short low-resolution drive per kind (320x240, 30 fps, MPEG-2 IBBBP, real
// encoder and MV reader) through the yardstick's own per-drive evaluation
// (lab/eval/drive_eval.h: up to scale and once per metric scale source).
//
// Bounds: what the pipeline achieves today with margin (docs/TRAJECTORY.md
// "Scene-kind end-to-end tests"), tight enough that a broken pipeline fails:
// no poses, poses only late, or a trajectory that does not follow the truth.
// The rural road and the highway have no plane for long stretches at this
// size: they track through motion-only steps (PipelineOptions::
// motion_only_steps), and without them they do not initialise at all.
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>

#include <gtest/gtest.h>

#include "lab/eval/drive_eval.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

DriveResult RunSmallDrive(SceneKind kind, int seed, const PipelineOptions& pipeline = {},
                          const std::string& profile = "mpeg2-ibbbp",
                          const std::function<void(SimulateOptions*)>& adjust = {}) {
  DriveSpec spec = MakeDriveSpec(kind, seed);
  spec.name = "e2e-" + spec.name;
  SimulateOptions& o = spec.sim;
  o.duration_s = 3.0;
  o.fps = 30.0;
  o.width_px = 320;
  o.height_px = 240;
  o.hfov_deg = 70.0;
  o.supersampling = 1;
  o.blur_px = 0.0;
  if (adjust) adjust(&o);
  DriveEvalOptions eo;
  eo.pipeline = pipeline;
  eo.profile = profile;
  eo.out_dir = testing::MakeTempDir("scene_kinds_e2e");
  eo.reuse = false;
  auto r = EvaluateDrive(spec, eo);
  std::filesystem::remove_all(eo.out_dir);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  if (!r.ok()) return DriveResult{};
  std::printf(
      "%s: %d/%d frames posed, first pose %.2f s, %d/%d pairs, D %.1f m, ATE %.3f m (%.2f %%), "
      "eps_D %.2f %%, scale err height %s%.3f speed %s%.3f first %s%.3f, planes measured %.0f "
      "%% of the steps, note '%s'\n",
      spec.name.c_str(), r->posed_frames, r->frames, r->first_pose_s, r->tracked_pairs,
      r->anchor_pairs, r->distance_m, r->ate_m,
      r->distance_m > 0 ? 100 * r->ate_m / r->distance_m : 0.0, 100 * r->eps_D,
      r->metric[0] ? "" : "(not metric) ", r->scale_error[0], r->metric[1] ? "" : "(not metric) ",
      r->scale_error[1], r->metric[2] ? "" : "(not metric) ", r->scale_error[2],
      100 * r->scale_support.PlaneStepShare(), r->note.c_str());
  return *r;
}

// A kind where today's pipeline tracks: poses from the first second on, for
// most anchors, following the truth.
void ExpectTracks(const DriveResult& r, double max_ate_frac, double max_eps_D,
                  int max_untracked_pairs = 3) {
  ASSERT_TRUE(r.evaluated) << r.spec.name << ": fewer than 3 poses";
  EXPECT_GE(r.first_pose_frame, 0);
  EXPECT_LE(r.first_pose_s, 1.0);
  EXPECT_GE(r.tracked_pairs, r.anchor_pairs - max_untracked_pairs);
  EXPECT_GT(r.distance_m, 5.0);
  EXPECT_LT(r.ate_m, max_ate_frac * r.distance_m);
  EXPECT_LT(r.eps_D, max_eps_D);
  // The first-step and speed sources are metric from the start; their scale
  // is the truth's within the drift the up-to-scale run has.
  EXPECT_TRUE(r.metric[kScaleFirstStep]);
  EXPECT_TRUE(r.metric[kScaleSpeed]);
  EXPECT_LT(std::abs(r.scale_error[kScaleFirstStep]), 0.5);
  // The run's scale support counts each tracked step once, as its anchor
  // pose's kind says (the first pose is no step), and the steps the road in
  // the B frames measured.
  EXPECT_EQ(r.scale_support.anchor_steps, r.tracked_pairs);
  EXPECT_EQ(r.scale_support.plane_steps, r.tracked_pairs - r.motion_only_anchors -
                                             r.coasting_anchors + r.scale_support.road_frame_steps);
}

// A kind that has no plane for long stretches: it tracks (as ExpectTracks)
// through motion-only anchors, and without them (the paper's method) far
// fewer pairs track, each untracked pair saying why.
// Returns the run with motion-only anchors.
DriveResult ExpectTracksWithoutPlanes(SceneKind kind, int max_untracked_pairs) {
  const DriveResult r = RunSmallDrive(kind, 2);
  ExpectTracks(r, 0.05, 0.12, max_untracked_pairs);
  EXPECT_GT(r.motion_only_anchors, 0);
  PipelineOptions paper;
  paper.motion_only_steps = false;
  const DriveResult without = RunSmallDrive(kind, 2, paper);
  EXPECT_LT(without.tracked_pairs + 3, r.tracked_pairs);
  EXPECT_FALSE(without.note.empty());
  EXPECT_EQ(without.motion_only_anchors, 0);
  return r;
}

// Today (docs/TRAJECTORY.md): urban ATE 1.5 %, eps_D 8.0 %; avenue 0.4 %, 1.2 %.
TEST(SceneKindsEndToEndTest, Urban) {
  const DriveResult r = RunSmallDrive(SceneKind::kUrban, 2);
  ExpectTracks(r, 0.05, 0.12);
  EXPECT_FALSE(r.scale_support.Weak()) << r.scale_support.Summary();  // planes on 83-91 %
}
TEST(SceneKindsEndToEndTest, Avenue) {
  const DriveResult r = RunSmallDrive(SceneKind::kAvenue, 2);
  ExpectTracks(r, 0.05, 0.12);
  EXPECT_FALSE(r.scale_support.Weak()) << r.scale_support.Summary();  // planes on 83-91 %
}
// Measured: rural 90 of 90 frames posed from 0 s, ATE 0.23 %, eps_D 4.3 %
// (2.6 % and 5.0 % without the road from the frames, below);
// highway 74 of 90 from 0.53 s (its first 4 pairs have no reliable motion:
// 4 untracked pairs allowed, all within the first second), ATE 0.58 %,
// eps_D 3.3 %. Without motion-only steps neither initialised.
TEST(SceneKindsEndToEndTest, RuralWithoutPlanes) {
  const DriveResult r = ExpectTracksWithoutPlanes(SceneKind::kRural, 3);
  // No plane of an anchor pair measured a step; the road in the B frames
  // did (RoadFromFramesMeasuresTheSteps below: without it the run says its
  // scale is the motion model's).
  EXPECT_GT(r.scale_support.road_frame_steps, 0);
  EXPECT_EQ(r.scale_support.plane_steps, r.scale_support.road_frame_steps);
}
// The road from the frames between the anchors (PipelineOptions::
// road_from_frames) on MPEG-2 IBBBP drives whose anchor pairs never show a
// plane: on the rural road (whose pairs have motion) the step lengths
// follow the road seen by the B frames next to the earlier anchor instead
// of the motion model's constant speed: ATE 0.23 % against 2.57 % of the
// distance. Most of the highway's pairs have no motion measured, so the
// road is not fitted there (a fit on the predicted motion followed
// its drift: ATE 1.84 % against 0.45 %): the same run with and without.
// The rural road measured in the frames also places a camera height's
// metric scale (Pipeline::MaybeFixScaleFromMeasuredRoad: the window never
// sees it in an anchor pair): measured 0.5 % off; without the stage the run
// stays up to scale and says so.
TEST(SceneKindsEndToEndTest, RoadFromFramesMeasuresTheSteps) {
  PipelineOptions off;
  off.road_from_frames = false;
  const DriveResult rural = RunSmallDrive(SceneKind::kRural, 2);
  const DriveResult rural_off = RunSmallDrive(SceneKind::kRural, 2, off);
  ASSERT_TRUE(rural.evaluated && rural_off.evaluated);
  EXPECT_LT(rural.ate_m, 0.01 * rural.distance_m);
  EXPECT_LT(rural.ate_m, 0.3 * rural_off.ate_m);
  // The road in the frames measured 16 of the 23 steps, one fewer since a
  // road step that moves |t| against its innovation is refused: just under
  // ScaleSupport's weak line (0.7); none without it.
  EXPECT_GT(rural.scale_support.PlaneStepShare(), 0.6) << rural.scale_support.Summary();
  EXPECT_TRUE(rural_off.scale_support.Weak()) << rural_off.scale_support.Summary();
  EXPECT_EQ(rural_off.scale_support.road_frame_steps, 0);
  ASSERT_TRUE(rural.metric[kScaleCameraHeight]);
  EXPECT_LT(std::abs(rural.scale_error[kScaleCameraHeight]), 0.03);
  EXPECT_FALSE(rural_off.metric[kScaleCameraHeight]);
  // Without poses for the frames between the anchors (anchors only) the B
  // frames are still read for the road: the same anchors.
  PipelineOptions anchors_only;
  anchors_only.frame_poses.enabled = false;
  const DriveResult rural_anchors = RunSmallDrive(SceneKind::kRural, 2, anchors_only);
  ASSERT_TRUE(rural_anchors.evaluated);
  EXPECT_EQ(rural_anchors.scale_support.road_frame_steps, rural.scale_support.road_frame_steps);
  EXPECT_NEAR(rural_anchors.anchor_ate_m, rural.anchor_ate_m, 1e-9);
  const DriveResult highway = RunSmallDrive(SceneKind::kHighway, 2);
  const DriveResult highway_off = RunSmallDrive(SceneKind::kHighway, 2, off);
  ASSERT_TRUE(highway.evaluated && highway_off.evaluated);
  EXPECT_LT(highway.ate_m, 1.2 * highway_off.ate_m + 0.02);
}
TEST(SceneKindsEndToEndTest, HighwayWithoutPlanes) {
  ExpectTracksWithoutPlanes(SceneKind::kHighway, 4);
}
TEST(SceneKindsEndToEndTest, Plaza) {
  const DriveResult r = RunSmallDrive(SceneKind::kPlaza, 2);
  ExpectTracks(r, 0.05, 0.12);
  EXPECT_FALSE(r.scale_support.Weak()) << r.scale_support.Summary();  // planes on 83-91 %
}
TEST(SceneKindsEndToEndTest, Intersection) {
  const DriveResult r = RunSmallDrive(SceneKind::kIntersection, 2);
  ExpectTracks(r, 0.05, 0.12);
  EXPECT_FALSE(r.scale_support.Weak()) << r.scale_support.Summary();  // planes on 83-91 %
}

// A braking urban drive at 10 fps (the evaluation's tuning drive urban-9 as
// it is: 640x480, 5 s): the road is measured in the B frames on most steps.
// Right after a new facade's first update, one such measurement (13 %
// short) lengthened the step by 22 % through the filter's correlations and
// put the road 51 % farther; the scale kept that jump (ATE 3.25 %, eps_D
// 6.7 %). Refused (PlaneEkf::UpdateRoadStep): ATE 0.84 %, eps_D 2.1 %.
TEST(SceneKindsEndToEndTest, BrakingUrbanDriveKeepsItsScaleWhenFacadesChange) {
  const DriveSpec urban9 = MakeDriveSpec(SceneKind::kUrban, 9);
  const DriveResult r = RunSmallDrive(SceneKind::kUrban, 9, {}, "mpeg2-ibbbp",
                                      [&](SimulateOptions* o) { *o = urban9.sim; });
  ASSERT_TRUE(r.evaluated);
  EXPECT_EQ(r.posed_frames, r.frames);
  EXPECT_LT(r.ate_m, 0.015 * r.distance_m);
  EXPECT_LT(r.eps_D, 0.04);
}

// H.264 IPPP: every frame is an anchor pair, one frame (33 ms) apart. The
// window refiner must not do worse than the filter alone there. With a motion
// prior whose spread shrank with the step length (sigma ~ dt) it held each
// newest step at the previous velocity, and every refined step rescales the
// filter: ATE 0.525 m against 0.081 m without the window on avenue-3, 0.175
// against 0.060 m on intersection-3; with the random walk (sigma ~ sqrt(dt))
// 0.130 and 0.068 m (docs/METHOD.md "The refiner's motion prior and the
// anchor rate"). With the road's attitude held from one window's solve and
// its height from the first, intersection-3 went to 0.171 m; with both
// averaged over 8 solves, 0.069 m (docs/METHOD.md "The road's attitude").
TEST(SceneKindsEndToEndTest, WindowRefinerHoldsOnOneFramePairs) {
  for (SceneKind kind : {SceneKind::kAvenue, SceneKind::kIntersection}) {
    PipelineOptions filter_alone;
    filter_alone.window_refine = false;
    const DriveResult window = RunSmallDrive(kind, 3, {}, "h264-ippp");
    const DriveResult alone = RunSmallDrive(kind, 3, filter_alone, "h264-ippp");
    ExpectTracks(window, 0.02, 0.10);
    ASSERT_TRUE(alone.evaluated);
    EXPECT_LT(window.ate_m, 2.0 * alone.ate_m + 0.02) << window.spec.name;
  }
}

// With a metric camera height the window's gauge on its oldest step is
// loosened (WindowRefinerOptions::metric_gauge_step_rel_sigma) so that the
// road's height takes the scale; at the up-to-scale gauge the window held
// the filter's scale. Measured (height source's scale error, up-to-scale
// gauge -> metric gauge) on the 320x240 urban drive: 11.2 -> 7.6 %. Not on
// every drive: on the plaza drive of the same size 10.3 -> 11.2 % since the
// camera bounces (SimulateOptions::bounce_m); over the MPEG-2 tuning drives
// the runs beyond 3 % went 6 -> 4 of 35 (docs/TRAJECTORY.md "Session 34").
TEST(SceneKindsEndToEndTest, MetricHeightTakesTheScaleFromTheWindowGauge) {
  PipelineOptions held;
  held.refine.metric_gauge_step_rel_sigma = held.refine.gauge_step_rel_sigma;
  const DriveResult with = RunSmallDrive(SceneKind::kUrban, 2);
  const DriveResult without = RunSmallDrive(SceneKind::kUrban, 2, held);
  ASSERT_TRUE(with.metric[kScaleCameraHeight] && without.metric[kScaleCameraHeight]);
  EXPECT_LT(std::abs(with.scale_error[kScaleCameraHeight]),
            std::abs(without.scale_error[kScaleCameraHeight]) - 0.02)
      << with.spec.name;
}

// The car park of the two tests below: 3-4 m/s at 60 fps, `duration_s` long.
std::function<void(SimulateOptions*)> SlowCarPark(double duration_s) {
  return [duration_s](SimulateOptions* o) {
    o->fps = 60.0;
    o->duration_s = duration_s;
    o->min_speed_mps = 3.0;
    o->max_speed_mps = 4.0;
  };
}

// A car park at 11-14 km/h, 60 fps, H.264 IPPP: one frame moves the camera 5-7 cm,
// too little parallax to decide the pair's motion. While waiting to
// initialise, the pair is extended frame by frame
// (PipelineOptions::init_max_baseline_s) until the parallax decides it: posed
// from the first frame on. Without the extension the drive waits.
TEST(SceneKindsEndToEndTest, SlowDriveAt60FpsInitialisesOnAnExtendedBaseline) {
  const auto slow = SlowCarPark(2.0);
  PipelineOptions no_extension;
  no_extension.init_max_baseline_s = 0.0;
  const DriveResult r = RunSmallDrive(SceneKind::kPlaza, 2, {}, "h264-ippp", slow);
  const DriveResult without = RunSmallDrive(SceneKind::kPlaza, 2, no_extension, "h264-ippp", slow);
  ASSERT_TRUE(r.evaluated);
  EXPECT_EQ(r.first_pose_frame, 0);
  EXPECT_EQ(r.posed_frames, r.frames);
  EXPECT_LT(r.ate_m, 0.05 * r.distance_m);
  EXPECT_TRUE(without.first_pose_frame < 0 || without.first_pose_frame > 1)
      << "the extension is no longer what initialises this drive";
}

// The same car park, tracked for 3 s on one-frame pairs (min_pair_span_s 0;
// by default 3 frames are chained): a pair too short for its parallax is
// extended by the next frame (PipelineOptions::track_max_baseline_s) instead
// of coasting on the motion model. Every frame keeps its pose (the extended
// pair's frames come with the longer pair); fewer anchors coast, and the
// trajectory is no worse than coasting's.
TEST(SceneKindsEndToEndTest, SlowDriveAt60FpsTracksOnExtendedBaselinesInsteadOfCoasting) {
  const auto slow = SlowCarPark(3.0);
  PipelineOptions extend;
  extend.merge.min_pair_span_s = 0.0;
  PipelineOptions coast = extend;
  coast.track_max_baseline_s = 0.0;
  const DriveResult r = RunSmallDrive(SceneKind::kPlaza, 2, extend, "h264-ippp", slow);
  const DriveResult without = RunSmallDrive(SceneKind::kPlaza, 2, coast, "h264-ippp", slow);
  std::printf("extended %d pairs, coasting anchors %d (without: %d)\n", r.extended_pairs,
              r.coasting_anchors, without.coasting_anchors);
  ASSERT_TRUE(r.evaluated);
  ASSERT_TRUE(without.evaluated);
  // Most of the anchors coast without it; with it, most one-frame pairs are
  // extended and few anchors coast.
  EXPECT_GT(without.coasting_anchors, without.tracked_pairs / 2);
  EXPECT_GT(r.extended_pairs, 10 + without.extended_pairs);
  EXPECT_LT(r.coasting_anchors, without.coasting_anchors / 4);
  EXPECT_EQ(r.posed_frames, r.frames);
  EXPECT_EQ(without.posed_frames, without.frames);
  EXPECT_LT(r.ate_m, 1.1 * without.ate_m + 0.01);
}

}  // namespace
}  // namespace slapse
