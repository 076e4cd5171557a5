// The window refiner end to end (issue 12): a simulated MPEG-2 IBBBP street
// drive through the whole pipeline with the camera height as scale source,
// scored against the simulator's truth: the step-length ratio to the truth
// may not jump from one anchor step to the next, and the metric scale must
// hold (bounds and where they come from: at the EXPECTs).
#include <cstdio>
#include <vector>

#include <gtest/gtest.h>

#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "lab/eval/trajectory_eval.h"
#include "lab/gt/ground_truth.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

struct Outcome {
  int steps = 0, tracked = 0;
  bool metric = false;
  std::string scale_note;
  TrajectoryErrors errors;
  double max_jump = 0;
};

Outcome RunDrive(const testing::TestDrive& drive, const GroundTruth& gt,
                 const PipelineOptions& options) {
  Outcome out;
  auto reader = MvReader::Open(drive.video_path);
  EXPECT_TRUE(reader.ok()) << reader.status().ToString();
  if (!reader.ok()) return out;
  Pipeline pipeline(drive.intrinsics, (*reader)->info().mv_sigma_px(), options);
  FrameRecord frame;
  while ((*reader)->Next(&frame).ok()) {
    auto step = pipeline.Push(frame);
    EXPECT_TRUE(step.ok()) << step.status().ToString();
    if (!step.ok() || !step->has_value()) continue;
    ++out.steps;
    out.tracked += (*step)->tracking;
    if (!(*step)->scale_note.empty()) out.scale_note = (*step)->scale_note;
  }
  const std::vector<TimedPose> truth = TruthPoses(gt);
  auto errors = EvaluateTrajectory(pipeline.trajectory(), truth);
  EXPECT_TRUE(errors.ok()) << errors.status().ToString();
  if (!errors.ok()) return out;
  out.errors = *errors;
  out.metric = pipeline.metric();
  out.max_jump = MaxStepRatioJump(pipeline.trajectory(), truth, errors->sim3_scale);
  std::printf(
      "refine %d: tracked %d of %d, eps_D %.2f %%, ATE %.3f m over %.1f m, "
      "max step-ratio jump %.1f %%, metric %d, scale %.3f (%s)\n",
      options.window_refine, out.tracked, out.steps, 100 * errors->eps_D, errors->ate_rmse_m,
      errors->distance_m, 100 * out.max_jump, out.metric, errors->sim3_scale,
      out.scale_note.c_str());
  return out;
}

TEST(RefineEndToEndTest, ScaleHoldsAndIsMetricFromTheCameraHeight) {
  SimulateOptions options;
  options.seed = 3;
  options.duration_s = 4.0;
  auto drive = testing::SimulateTestDrive("refine_e2e", options);
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  auto gt = LoadGroundTruth(drive->dir);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();

  PipelineOptions po;
  po.scale.source = ScaleOptions::Source::kCameraHeight;
  po.scale.camera_height_m = TrueCameraHeightM(*gt, 0);
  ASSERT_GT(po.scale.camera_height_m, 0.5);
  po.window_refine = true;
  const Outcome refined = RunDrive(*drive, *gt, po);
  po.window_refine = false;
  const Outcome ekf = RunDrive(*drive, *gt, po);

  EXPECT_GE(refined.tracked, refined.steps - 1);
  ASSERT_TRUE(refined.metric) << refined.scale_note;
  // The step-length ratio to the truth may not jump by more than 5 % from one
  // anchor step to the next. This drive: 1.9 % with the window, 7.7 % with
  // the EKF alone; bench/refine_eval's tuning drives (seeds 1-3, 5 s):
  // 2.9-5.5 % with the window, 7.2-9.8 % without; the street drive
  // jumped 30 % at a plane turnover.
  EXPECT_LT(refined.max_jump, 0.05);
  EXPECT_LT(refined.max_jump, ekf.max_jump);  // the window is what holds it
  // Metric scale from the camera height: this drive -2.6 %; +4.4 to +6.4 % on
  // the tuning drives (a bias both paths share: docs/METHOD.md); a scale fixed
  // from a wrong or stale plane is off by tens of percent (the issue:
  // 1.05-3.95x).
  EXPECT_NEAR(refined.errors.sim3_scale, 1.0, 0.08);
  EXPECT_LT(refined.errors.ate_rmse_m, 0.01 * refined.errors.distance_m);
}

}  // namespace
}  // namespace slapse
