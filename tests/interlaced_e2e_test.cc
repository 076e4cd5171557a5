// An interlaced camera end to end (issue 13): the same simulated drive coded
// as MPEG-2 progressive frames (mpeg2-ibbbp) and as an interlaced camera codes
// it (mpeg2-interlaced: the bottom field rendered half a frame after the top
// field, interlaced frame pictures with field or frame prediction per
// macroblock, top field first). Real encoder (libavcodec), real MV reader.
//
// Pinned: the vectors the reader yields for the interlaced stream agree with
// the truth's transfer through the road plane about as often as the
// progressive stream's (the field-predicted ones, which cannot be read in
// frame pixels, are dropped: docs/METHOD.md "MV reader"), and the pipeline
// tracks the interlaced drive with a bounded ATE.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <vector>

#include <gtest/gtest.h>

#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "lab/eval/trajectory_eval.h"
#include "lab/gt/ground_truth.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

constexpr uint64_t kSeed = 4;
constexpr double kDurationS = 3.0;

struct DriveRun {
  int64_t road_mvs = 0, road_within_1px = 0;  // P and B vectors on the road, against the truth
  std::vector<double> road_errors_px;
  ReadStats stats;
  bool interlaced = false;
  int steps = 0, tracked = 0;
  double distance_m = 0.0, ate_m = -1.0;
};

// The road's (plane 0) vectors of frame `f` against the true transfer into their reference.
void CountRoadVectors(const FrameRecord& f, const GroundTruth& gt, DriveRun* run) {
  for (const MotionVector& mv : f.mvs) {
    const int64_t ref = f.ReferenceIndex(mv);
    if (ref < 0 || gt.LabelAt(static_cast<int>(f.index), mv.x_px, mv.y_px) != 0) continue;
    Eigen::Vector2d x_ref;
    const Eigen::Vector2d x(mv.x_px, mv.y_px);
    if (!gt.TransferThroughPlane(0, static_cast<int>(f.index), static_cast<int>(ref), x, &x_ref)) {
      continue;
    }
    const double error_px = (x + Eigen::Vector2d(mv.dx_px, mv.dy_px) - x_ref).norm();
    ++run->road_mvs;
    run->road_within_1px += error_px <= 1.0;
    run->road_errors_px.push_back(error_px);
  }
}

DriveRun RunDrive(const std::string& preset) {
  DriveRun run;
  SimulateOptions o = testing::SmallMpeg2DriveOptions(kSeed, kDurationS);
  auto encoder = EncoderPreset(preset, o.fps);
  EXPECT_TRUE(encoder.ok()) << encoder.status().ToString();
  if (!encoder.ok()) return run;
  o.encoder = *encoder;
  auto drive = testing::SimulateTestDrive("interlaced_e2e", o);
  EXPECT_TRUE(drive.ok()) << drive.status().ToString();
  if (!drive.ok()) return run;
  auto gt = LoadGroundTruth(drive->dir);
  auto reader = MvReader::Open(drive->video_path);
  EXPECT_TRUE(gt.ok() && reader.ok());
  if (!gt.ok() || !reader.ok()) return run;

  Pipeline pipeline(drive->intrinsics, (*reader)->info().mv_sigma_px());
  FrameRecord frame;
  Status status;
  while ((status = (*reader)->Next(&frame)).ok()) {
    CountRoadVectors(frame, *gt, &run);
    auto step = pipeline.Push(frame);
    EXPECT_TRUE(step.ok()) << step.status().ToString();
    if (!step.ok() || !step->has_value()) continue;
    ++run.steps;
    run.tracked += (*step)->tracking;
  }
  EXPECT_EQ(status.code(), StatusCode::kOutOfRange) << status.ToString();
  run.stats = (*reader)->stats();
  run.interlaced = (*reader)->info().interlaced;

  std::vector<TimedPose> estimate;
  for (const auto& p : pipeline.trajectory()) {
    estimate.push_back({p.index, p.timestamp_s, p.world_from_cam});
  }
  const std::vector<TimedPose> truth = TruthPoses(*gt);
  run.distance_m =
      (truth.back().world_from_cam.translation - truth.front().world_from_cam.translation).norm();
  auto errors = EvaluateTrajectory(estimate, truth);
  if (errors.ok()) run.ate_m = errors->ate_rmse_m;
  std::filesystem::remove_all(drive->dir);
  std::vector<double>& e = run.road_errors_px;
  std::sort(e.begin(), e.end());
  std::printf("%s: road vector error median %.2f px, 75th %.2f px, 2 px share %.1f %%\n",
              preset.c_str(), e.empty() ? -1.0 : e[e.size() / 2],
              e.empty() ? -1.0 : e[3 * e.size() / 4],
              100.0 * (std::upper_bound(e.begin(), e.end(), 2.0) - e.begin()) /
                  std::max<size_t>(1, e.size()));
  std::printf(
      "%s: road vectors %lld, within 1 px of the truth %.1f %%; field-predicted dropped %lld, "
      "outside %lld; %d of %d pairs tracked; distance %.1f m, ATE %.3f m (%.2f %%)\n",
      preset.c_str(), static_cast<long long>(run.road_mvs),
      100.0 * run.road_within_1px / std::max<int64_t>(1, run.road_mvs),
      static_cast<long long>(run.stats.field_mvs_dropped),
      static_cast<long long>(run.stats.outside_mvs_dropped), run.tracked, run.steps, run.distance_m,
      run.ate_m, 100.0 * run.ate_m / std::max(1e-9, run.distance_m));
  return run;
}

double Share(const DriveRun& r) {
  return static_cast<double>(r.road_within_1px) / std::max<int64_t>(1, r.road_mvs);
}

TEST(InterlacedEndToEndTest, VectorsAgreeWithTheTruthAndTheDriveTracks) {
  const DriveRun progressive = RunDrive("mpeg2-ibbbp");
  const DriveRun interlaced = RunDrive("mpeg2-interlaced");
  EXPECT_FALSE(progressive.interlaced);
  EXPECT_EQ(progressive.stats.field_mvs_dropped, 0);
  ASSERT_TRUE(interlaced.interlaced);
  EXPECT_GT(interlaced.stats.field_mvs_dropped, 0);
  EXPECT_GT(interlaced.stats.outside_mvs_dropped, 0);  // 240 rows: a padded MB row

  ASSERT_GT(progressive.road_mvs, 1000);
  // Measured (seed 4, 3 s): progressive 16354 road vectors, 50.1 % within
  // 1 px of the truth (median error 1.00 px); interlaced 9611 kept (18516
  // field-predicted 16x8 vectors dropped), 42.1 % (median 1.25 px): the
  // frame-predicted vectors of woven fields are a little noisier. Keeping the
  // field-predicted vectors as FFmpeg exports them gives 21491 at 30.0 %
  // (median 1.93 px): this bound fails then.
  EXPECT_GT(interlaced.road_mvs, progressive.road_mvs / 2);
  EXPECT_GT(Share(interlaced), Share(progressive) - 0.12);

  // Measured: 23 of 23 pairs tracked, ATE 0.487 m over 27.4 m (1.77 %;
  // progressive: 0.442 m, 1.61 %).
  ASSERT_GT(interlaced.steps, 10);
  EXPECT_GE(interlaced.tracked, interlaced.steps - 2);
  EXPECT_GT(interlaced.distance_m, 10.0);
  ASSERT_GE(interlaced.ate_m, 0.0);
  EXPECT_LT(interlaced.ate_m, 0.03 * interlaced.distance_m);
}

}  // namespace
}  // namespace slapse
