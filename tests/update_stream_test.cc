// UpdateStream on a real Pipeline over a small simulated drive: every step
// gives one pose update with the step's pose; plane events are ADDED for a
// track the filter did not hold before, UPDATED for one it keeps, REMOVED
// for one it dropped (in that order, ascending ids); and a consumer that only
// applies the updates (as the server's snapshots do) holds exactly the
// pipeline's trajectory and plane map after every step, also across the
// step where the metric scale gets fixed and everything is rescaled; the same
// for the all-frames poses (Pipeline::poses(): added, or replaced by a later
// revision of the same frame index).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>
#include <vector>

#include "core/common/road.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "core/pipeline/update_stream.h"
#include "lab/gt/ground_truth.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

// What a consumer of the updates holds: the server's snapshots, in core types.
struct Mirror {
  std::vector<TimedPose> trajectory;
  std::vector<FramePose> poses;  // by ascending frame index
  std::map<int, MapPlane> planes;
  std::set<int> live;
  bool metric = false;
};

// Checks `u` against the step and the consumer's state before it, then
// applies it.
void CheckAndApply(const Pipeline& pipeline, const PipelineStep& step, const StepUpdates& u,
                   Mirror* m, int* rescales, std::map<PlaneChange::Kind, int>* kinds) {
  EXPECT_EQ(u.pose.anchor_index, step.later_index);
  EXPECT_EQ(u.pose.timestamp_s, step.timestamp_s);
  EXPECT_EQ(u.pose.tracking, step.tracking);
  EXPECT_EQ(u.pose.metric, step.metric);
  EXPECT_EQ(u.pose.note, step.note);
  EXPECT_EQ(u.pose.scale_note, step.scale_note);
  EXPECT_EQ(u.pose.world_from_cam.translation, step.world_from_cam.translation);

  std::set<int> now;
  for (const PlaneTrack& t : step.planes) now.insert(t.track_id);
  int last_id = -1;
  bool removing = false;
  for (const PlaneChange& c : u.planes) {
    SCOPED_TRACE("track " + std::to_string(c.track_id));
    ASSERT_NE(c.plane, nullptr);
    EXPECT_EQ(c.plane->track_id, c.track_id);
    EXPECT_EQ(c.anchor_index, step.later_index);
    ++(*kinds)[c.kind];
    switch (c.kind) {
      case PlaneChange::Kind::kAdded:
        EXPECT_TRUE(now.count(c.track_id) && !m->live.count(c.track_id));
        break;
      case PlaneChange::Kind::kUpdated:
        EXPECT_TRUE(now.count(c.track_id) && m->live.count(c.track_id));
        break;
      case PlaneChange::Kind::kRemoved:
        EXPECT_TRUE(!now.count(c.track_id) && m->live.count(c.track_id));
        break;
    }
    // Ascending ids, the REMOVED ones after the others.
    const bool removed = c.kind == PlaneChange::Kind::kRemoved;
    if (removed && !removing) {
      removing = true;
      last_id = -1;
    }
    EXPECT_EQ(removed, removing);
    EXPECT_GT(c.track_id, last_id);
    last_id = c.track_id;
  }
  // Every live or previously live track the map holds has its event.
  size_t expected = 0;
  for (int id : now) expected += pipeline.plane_map().count(id);
  for (int id : m->live) expected += !now.count(id) && pipeline.plane_map().count(id);
  EXPECT_EQ(u.planes.size(), expected);
  m->live = now;

  EXPECT_EQ(u.metric, pipeline.metric());
  if (u.rescaled) {
    ++*rescales;
    EXPECT_NE(u.metric, m->metric);
    ASSERT_NE(u.plane_map, nullptr);
    m->trajectory.clear();
    m->poses.clear();
    m->planes = *u.plane_map;
  } else {
    EXPECT_EQ(u.metric, m->metric);
  }
  m->metric = u.metric;
  for (const TimedPose& p : u.new_points) m->trajectory.push_back(p);
  for (const FramePose& p : u.frame_poses) {
    auto it =
        std::lower_bound(m->poses.begin(), m->poses.end(), p.pose.index,
                         [](const FramePose& q, int64_t index) { return q.pose.index < index; });
    if (it != m->poses.end() && it->pose.index == p.pose.index) {
      EXPECT_GT(p.revision, it->revision) << "frame " << p.pose.index;
      *it = p;
    } else {
      EXPECT_TRUE(it == m->poses.end()) << "frame " << p.pose.index << " out of order";
      m->poses.push_back(p);
    }
  }
  // Besides revisions, the new poses are the step's own.
  if (!u.rescaled) {
    size_t fresh = 0;
    for (const FramePose& p : u.frame_poses) fresh += p.revision == 0;
    EXPECT_EQ(fresh, step.frame_poses.size());
  }
  for (const PlaneChange& c : u.planes) m->planes[c.track_id] = *c.plane;
}

// The pipeline holds the tail of what the mirror holds (Pipeline::ForgetFinal
// drops the head; pose numbers stay absolute).
void ExpectMirrorsPipeline(const Mirror& m, const Pipeline& pipeline) {
  const auto& traj = pipeline.trajectory();
  const size_t anchors_base = pipeline.anchors_forgotten();
  ASSERT_EQ(m.trajectory.size(), anchors_base + traj.size());
  for (size_t i = 0; i < traj.size(); ++i) {
    const TimedPose& mt = m.trajectory[anchors_base + i];
    EXPECT_EQ(mt.index, traj[i].index);
    EXPECT_EQ(mt.timestamp_s, traj[i].timestamp_s);
    EXPECT_EQ(mt.world_from_cam.translation, traj[i].world_from_cam.translation);
    EXPECT_EQ(mt.world_from_cam.rotation.coeffs(), traj[i].world_from_cam.rotation.coeffs());
  }
  const auto& poses = pipeline.poses();
  const size_t base = pipeline.poses_forgotten();
  ASSERT_EQ(m.poses.size(), base + poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    const FramePose& mp = m.poses[base + i];
    EXPECT_EQ(mp.pose.index, poses[i].pose.index);
    EXPECT_EQ(mp.pose.timestamp_s, poses[i].pose.timestamp_s);
    EXPECT_EQ(mp.pose.world_from_cam.translation, poses[i].pose.world_from_cam.translation);
    EXPECT_EQ(mp.quality.kind, poses[i].quality.kind);
    EXPECT_EQ(mp.revision, poses[i].revision);
  }
  ASSERT_EQ(m.planes.size(), pipeline.planes_forgotten() + pipeline.plane_map().size());
  for (const auto& [id, p] : pipeline.plane_map()) {
    ASSERT_TRUE(m.planes.count(id)) << id;
    const MapPlane& q = m.planes.at(id);
    EXPECT_EQ(q.normal_world, p.normal_world) << id;
    EXPECT_EQ(q.distance_m, p.distance_m) << id;
    EXPECT_EQ(q.first_seen_s, p.first_seen_s) << id;
    EXPECT_EQ(q.last_seen_s, p.last_seen_s) << id;
    EXPECT_EQ(q.observations, p.observations) << id;
  }
}

class UpdateStreamTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto drive =
        testing::SimulateTestDrive("update_stream", testing::SmallMpeg2DriveOptions(31, 3.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    drive_ = new testing::TestDrive(*drive);
  }
  static void TearDownTestSuite() {
    delete drive_;
    drive_ = nullptr;
  }

  // The drive's camera at the stream's frame size.
  static Intrinsics StreamIntrinsics(const StreamInfo& info) {
    Intrinsics k = drive_->intrinsics;
    k.width_px = info.width_px;
    k.height_px = info.height_px;
    return k;
  }

  // Runs the drive through a Pipeline with `options`, checking the updates
  // after every step; returns the rescales seen.
  // revise_every > 0: after every that many steps, the latest FRAME pose
  // still revisable is revised (moved by 1 cm), as a window refiner would;
  // *revisions counts the revised poses the updates carried.
  // keep_final >= 0: after every step, Pipeline::ForgetFinal(keep_final);
  // *forgotten is then the poses it dropped by the end.
  void Run(const PipelineOptions& options, int* rescales, int revise_every = 0,
           int* revisions = nullptr, int keep_final = -1, size_t* forgotten = nullptr) {
    ASSERT_NE(drive_, nullptr);
    auto reader = MvReader::Open(drive_->video_path);
    ASSERT_TRUE(reader.ok()) << reader.status().ToString();
    const StreamInfo& info = (*reader)->info();
    const Intrinsics k = StreamIntrinsics(info);
    Pipeline pipeline(k, info.mv_sigma_px(), options);
    UpdateStream stream;
    Mirror mirror;
    std::map<PlaneChange::Kind, int> kinds;
    FrameRecord frame;
    int steps = 0;
    while ((*reader)->Next(&frame).ok()) {
      auto step = pipeline.Push(frame);
      ASSERT_TRUE(step.ok()) << step.status().ToString();
      if (!step->has_value()) continue;
      ++steps;
      SCOPED_TRACE("step at anchor " + std::to_string((*step)->later_index));
      const StepUpdates u = stream.Next(pipeline, **step);
      CheckAndApply(pipeline, **step, u, &mirror, rescales, &kinds);
      ExpectMirrorsPipeline(mirror, pipeline);
      for (const FramePose& p : u.frame_poses) {
        if (revisions != nullptr && p.revision > 0) ++*revisions;
      }
      if (keep_final >= 0) {
        const bool may_change = pipeline.ScaleMayChange();
        pipeline.ForgetFinal(static_cast<size_t>(keep_final));
        // Nothing goes while a rescale could still need it; then the final
        // poses kept stay bounded.
        if (may_change) {
          EXPECT_EQ(pipeline.poses_forgotten(), 0u);
        }
        EXPECT_LE(pipeline.first_revisable_pose() - pipeline.poses_forgotten(),
                  may_change ? pipeline.first_revisable_pose() : 2u * keep_final + 16);
        if (forgotten != nullptr) *forgotten = pipeline.poses_forgotten();
      }
      if (revise_every > 0 && steps % revise_every == 0) {
        const auto& poses = pipeline.poses();
        const size_t base = pipeline.poses_forgotten();
        for (size_t n = base + poses.size(); n-- > pipeline.first_revisable_pose();) {
          if (poses[n - base].quality.kind != PoseKind::kFrame) continue;
          Rigid3d moved = poses[n - base].pose.world_from_cam;
          moved.translation.x() += 0.01;
          ASSERT_TRUE(pipeline.RevisePose(n, moved).ok());
          break;
        }
        if (pipeline.first_revisable_pose() > 0) {  // final poses stay final
          EXPECT_EQ(pipeline.RevisePose(0, Rigid3d()).code(), StatusCode::kFailedPrecondition);
        }
      }
      if (HasFatalFailure()) return;
    }
    EXPECT_GT(steps, 5);
    // A drive has planes that come, stay and go.
    EXPECT_GT(kinds[PlaneChange::Kind::kAdded], 0);
    EXPECT_GT(kinds[PlaneChange::Kind::kUpdated], 0);
  }

  static testing::TestDrive* drive_;
};

testing::TestDrive* UpdateStreamTest::drive_ = nullptr;

TEST_F(UpdateStreamTest, UpToScaleEventsAndSnapshots) {
  int rescales = 0;
  Run(PipelineOptions{}, &rescales);
  EXPECT_EQ(rescales, 0);
}

TEST_F(UpdateStreamTest, FixedScaleResendsTheRescaledSnapshots) {
  PipelineOptions o;
  o.scale.source = ScaleOptions::Source::kFirstStep;
  o.scale.first_step_m = 2.0;
  int rescales = 0;
  Run(o, &rescales);
  EXPECT_EQ(rescales, 1);
}

// Poses revised between steps (as a window refiner revises anchors and the
// frames between) go out again with a higher revision and replace the
// consumer's copy: the mirror still equals Pipeline::poses() after every step.
TEST_F(UpdateStreamTest, RevisedPosesAreSentAgain) {
  PipelineOptions o;
  o.revisable_tail_poses = 12;
  int rescales = 0, revisions = 0;
  Run(o, &rescales, 3, &revisions);
  EXPECT_GT(revisions, 3);
}

// Bounded memory (the service's long sessions): forgetting the final poses
// after every step changes nothing a consumer of the updates sees -- the
// mirror equals what the pipeline forgot followed by what it holds, after
// every step, with revisions going on in the revisable tail.
TEST_F(UpdateStreamTest, ForgettingFinalPosesLosesNothingSent) {
  PipelineOptions o;
  o.revisable_tail_poses = 12;
  int rescales = 0, revisions = 0;
  size_t forgotten = 0;
  Run(o, &rescales, 3, &revisions, /*keep_final=*/4, &forgotten);
  EXPECT_GT(revisions, 3);
  EXPECT_GT(forgotten, 40u);
}

// Under the camera-height source nothing is forgotten until the scale is
// fixed (a rescale re-sends everything) or its road_deadline_s passed; then
// forgetting starts, and the updates still mirror the run.
TEST_F(UpdateStreamTest, NothingIsForgottenWhileTheScaleMayChange) {
  PipelineOptions o;
  o.scale.source = ScaleOptions::Source::kCameraHeight;
  o.scale.camera_height_m = 1.5;
  o.scale.road_deadline_s = 0.5;
  int rescales = 0;
  size_t forgotten = 0;
  Run(o, &rescales, 0, nullptr, /*keep_final=*/4, &forgotten);
  EXPECT_LE(rescales, 1);
  EXPECT_GT(forgotten, 20u);
}

// The step that fixes the camera-height scale says how steeply the image saw
// the road (core/common/road.h SteepestRoadDepressionDeg of the window's
// road), and the pose update carries that note; the angle is the truth's
// within a degree and a half (the window's road attitude), and the note
// calls the scale weak exactly below ScaleOptions::kMinRoadDepressionDeg.
TEST_F(UpdateStreamTest, TheHeightFixSaysHowSteeplyTheRoadWasSeen) {
  ASSERT_NE(drive_, nullptr);
  auto gt = LoadGroundTruth(drive_->dir);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  auto reader = MvReader::Open(drive_->video_path);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  const StreamInfo& info = (*reader)->info();
  const Intrinsics k = StreamIntrinsics(info);
  PipelineOptions o;
  o.scale.source = ScaleOptions::Source::kCameraHeight;
  o.scale.camera_height_m = gt->frames[0].world_from_cam.translation.z();
  Pipeline pipeline(k, info.mv_sigma_px(), o);
  UpdateStream stream;
  FrameRecord frame;
  std::string fix_note;
  int64_t fix_index = -1;
  while ((*reader)->Next(&frame).ok()) {
    auto step = pipeline.Push(frame);
    ASSERT_TRUE(step.ok()) << step.status().ToString();
    if (!step->has_value() || fix_index >= 0 || !pipeline.metric()) continue;
    fix_index = (*step)->later_index;
    fix_note = stream.Next(pipeline, **step).pose.scale_note;
  }
  ASSERT_GE(fix_index, 0) << "the camera height never fixed the scale";
  ASSERT_TRUE(pipeline.height_road_depression_deg().has_value());
  const double seen_deg = *pipeline.height_road_depression_deg();
  // The truth: the world's down (road at z = 0) in the fixing camera.
  const Eigen::Vector3d down_cam =
      gt->frames[fix_index].world_from_cam.R().transpose() * Eigen::Vector3d(0, 0, -1);
  const double truth_deg = SteepestRoadDepressionDeg(down_cam, k);
  std::printf("height fixed at anchor %lld: road seen down to %.2f deg (truth %.2f)\n",
              static_cast<long long>(fix_index), seen_deg, truth_deg);
  EXPECT_NEAR(seen_deg, truth_deg, 1.5);
  EXPECT_EQ(fix_note.rfind("metric: camera height", 0), 0u) << fix_note;
  EXPECT_NE(fix_note.find("below its horizon"), std::string::npos) << fix_note;
  EXPECT_EQ(fix_note.find("weak") != std::string::npos, ScaleOptions::HeightScaleWeak(seen_deg))
      << fix_note;
}

// A loss (the stream breaks off and 12 frames never arrive): the trajectory
// restarts in the same world on a later pair, and the anchor it restarts on
// says so (gap_frames = the frames without a pose before it, a note) instead
// of a silent gap.
TEST_F(UpdateStreamTest, ALossIsAVisibleRestart) {
  ASSERT_NE(drive_, nullptr);
  auto reader = MvReader::Open(drive_->video_path);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  const StreamInfo& info = (*reader)->info();
  const Intrinsics k = StreamIntrinsics(info);
  Pipeline pipeline(k, info.mv_sigma_px());
  FrameRecord frame;
  bool broke = false;
  int64_t last_posed_before = -1;
  while ((*reader)->Next(&frame).ok()) {
    if (!broke && frame.index == 40) {
      ASSERT_FALSE(pipeline.poses().empty());
      last_posed_before = pipeline.poses().back().pose.index;
      pipeline.Break();
      broke = true;
    }
    if (broke && frame.index < 52) continue;  // lost
    ASSERT_TRUE(pipeline.Push(frame).ok());
  }
  ASSERT_TRUE(broke);
  int restarts = 0;
  for (const FramePose& p : pipeline.poses()) {
    if (p.pose.index <= last_posed_before || p.quality.gap_frames == 0) continue;
    ++restarts;
    EXPECT_GE(p.pose.index, 52);
    EXPECT_EQ(p.quality.gap_frames, p.pose.index - last_posed_before - 1);
    EXPECT_NE(p.quality.note.find("re-initialised"), std::string::npos) << p.quality.note;
  }
  EXPECT_EQ(restarts, 1);
  // It goes on after the restart.
  EXPECT_GT(pipeline.poses().back().pose.index, 70);
  // ... at the speed it had: the first step after the restart carries the
  // last step's speed (its length over its time), the drive's speed being
  // nearly constant over the lost half second.
  const auto& anchors = pipeline.trajectory();
  auto speed = [&](size_t i) {
    return (anchors[i + 1].world_from_cam.translation - anchors[i].world_from_cam.translation)
               .norm() /
           (anchors[i + 1].timestamp_s - anchors[i].timestamp_s);
  };
  size_t restart = 0;
  while (restart < anchors.size() && anchors[restart].index <= last_posed_before) ++restart;
  ASSERT_GE(restart, 2u);
  ASSERT_LT(restart + 1, anchors.size());
  EXPECT_NEAR(speed(restart) / speed(restart - 2), 1.0, 0.15);
}

}  // namespace
}  // namespace slapse
