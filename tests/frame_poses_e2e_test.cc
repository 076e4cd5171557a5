// Per-frame poses end to end: the simulated MPEG-2 IBBBP drive of
// trajectory_e2e_test (seed 3, a tuning seed) through the whole pipeline;
// every frame after the first second up to the last anchor must have a pose,
// most of the frames between anchors from their own vectors (FRAME), the
// frames' position error (in the anchors' own Sim(3) alignment) within a
// bound of the anchors', and no pose far from the truth. The numbers of this
// drive and the reporting seeds are in docs/TRAJECTORY.md "Per-frame poses".
#include <cmath>
#include <cstdio>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "core/pipeline/result_io.h"
#include "lab/eval/frame_pose_eval.h"
#include "lab/eval/trajectory_eval.h"
#include "lab/gt/ground_truth.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

TEST(FramePosesEndToEndTest, EveryFrameHasAPoseNearTheTruth) {
  SimulateOptions options;
  options.seed = 3;
  options.duration_s = 4.0;
  auto drive = testing::SimulateTestDrive("frame_poses_e2e", options);
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  auto gt = LoadGroundTruth(drive->dir);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  auto reader = MvReader::Open(drive->video_path);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();

  Pipeline pipeline(drive->intrinsics, (*reader)->info().mv_sigma_px());
  std::vector<double> frame_times;
  FrameRecord frame;
  Status status;
  while ((status = (*reader)->Next(&frame)).ok()) {
    frame_times.push_back(frame.timestamp_s);
    auto step = pipeline.Push(frame);
    ASSERT_TRUE(step.ok()) << step.status().ToString();
  }
  ASSERT_EQ(status.code(), StatusCode::kOutOfRange) << status.ToString();

  // Every frame from 1 s to the last anchor has exactly one pose, in order.
  const std::vector<FramePose>& poses = pipeline.poses();
  ASSERT_FALSE(poses.empty());
  std::set<int64_t> posed;
  for (size_t i = 0; i < poses.size(); ++i) {
    if (i > 0) {
      EXPECT_GT(poses[i].pose.index, poses[i - 1].pose.index);
    }
    posed.insert(poses[i].pose.index);
  }
  const int64_t last_anchor = pipeline.trajectory().back().index;
  int expected = 0, frames = 0;
  for (int64_t i = 0; i <= last_anchor; ++i) {
    if (frame_times[i] < 1.0) continue;
    ++expected;
    EXPECT_TRUE(posed.count(i)) << "frame " << i << " at " << frame_times[i] << " s has no pose";
  }
  for (const FramePose& p : poses) frames += p.quality.kind == PoseKind::kFrame;
  EXPECT_GT(expected, 60);

  auto errors = EvaluateFramePoses(poses, TruthPoses(*gt));
  ASSERT_TRUE(errors.ok()) << errors.status().ToString();
  std::printf(
      "poses %zu (FRAME %d), anchors RMSE %.3f m max %.3f m; frames RMSE %.3f m max %.3f m; "
      "interpolating them instead %.3f m; interpolated %d\n",
      poses.size(), frames, errors->anchor.rmse_m, errors->anchor.max_m, errors->frame.rmse_m,
      errors->frame.max_m, errors->frame_baseline.rmse_m, errors->interpolated.poses);
  // Most frames between anchors get their own estimate, each with a finite sigma.
  const int between =
      static_cast<int>(poses.size()) - static_cast<int>(pipeline.trajectory().size());
  EXPECT_GE(frames, 0.8 * between);
  for (const FramePose& p : poses) {
    if (p.quality.kind != PoseKind::kFrame) continue;
    EXPECT_TRUE(std::isfinite(p.quality.position_sigma) && p.quality.position_sigma > 0);
    EXPECT_GE(p.quality.inliers, FramePoseOptions().min_inliers);
  }
  // run's files: the TUM file stays valid TUM (8 numbers a line, increasing
  // timestamps), the quality CSV has one row per TUM line, kind by kind.
  std::ostringstream tum, csv;
  WriteTrajectoryTum(TimedPosesOf(poses), tum);
  WritePoseQualityCsv(poses, csv);
  std::istringstream tum_in(tum.str()), csv_in(csv.str());
  std::string line, row;
  ASSERT_TRUE(std::getline(csv_in, row));
  EXPECT_EQ(row,
            "frame_index,timestamp_s,kind,position_sigma,inliers,rms_px,revision,gap_frames,note");
  double last_t = -1;
  size_t lines = 0;
  while (std::getline(tum_in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::vector<double> v;
    double x;
    while (fields >> x) v.push_back(x);
    ASSERT_EQ(v.size(), 8u) << line;
    EXPECT_GT(v[0], last_t);
    last_t = v[0];
    ASSERT_TRUE(std::getline(csv_in, row));
    ASSERT_LT(lines, poses.size());
    EXPECT_EQ(row.rfind(std::to_string(poses[lines].pose.index) + ",", 0), 0u) << row;
    EXPECT_NE(row.find(std::string(",") + PoseKindName(poses[lines].quality.kind) + ","),
              std::string::npos)
        << row;
    ++lines;
  }
  EXPECT_EQ(lines, poses.size());
  EXPECT_FALSE(std::getline(csv_in, row));

  // Relative to their anchors (free of the anchors' drift): the frames'
  // own vectors must not make the rotation worse than interpolating, nor
  // move the position off it by more than a few millimetres.
  std::printf(
      "local to the anchors: position %.4f m (interpolated %.4f m), rotation %.4f deg "
      "(interpolated %.4f deg)\n",
      errors->frame_local.rmse_m, errors->frame_baseline_local.rmse_m,
      errors->frame_local.rot_rmse_deg, errors->frame_baseline_local.rot_rmse_deg);
  EXPECT_LT(errors->frame_local.rot_rmse_deg, errors->frame_baseline_local.rot_rmse_deg);
  EXPECT_LT(errors->frame_local.rmse_m, 2.0 * errors->frame_baseline_local.rmse_m + 0.003);

  // The frames' error: within 1.5x the anchors' (they hang between them),
  // and no pose far from the truth.
  EXPECT_LT(errors->frame.rmse_m, 1.5 * errors->anchor.rmse_m + 0.02);
  EXPECT_LT(errors->all.max_m, 2.0 * errors->anchor.max_m + 0.05);
}

}  // namespace
}  // namespace slapse
