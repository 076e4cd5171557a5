// The front end (core/pipeline/front_end.h) on a simulated MPEG-2 drive: it
// computes what the stages chained by hand compute (merge, the pair motion
// seeded by the previous pair's, the plane-at-infinity threshold, extraction),
// the pipeline's steps carry exactly its planes, and Reset forgets the prior
// and the tracks.
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/merge/mv_merge.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/front_end.h"
#include "core/pipeline/pipeline.h"
#include "core/planes/infinity.h"
#include "core/planes/plane_extraction.h"
#include "lab/codec/video_encoder.h"
#include "lab/gt/ground_truth.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

class FrontEndTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto drive = testing::SimulateTestDrive("front_end", testing::SmallMpeg2DriveOptions(4, 2.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    drive_ = new testing::TestDrive(*drive);
  }
  static void TearDownTestSuite() {
    delete drive_;
    drive_ = nullptr;
  }
  static std::vector<FrameRecord> Frames() {
    auto reader = MvReader::Open(drive_->video_path);
    EXPECT_TRUE(reader.ok()) << reader.status().ToString();
    std::vector<FrameRecord> frames;
    FrameRecord f;
    while ((*reader)->Next(&f).ok()) frames.push_back(f);
    sigma_px_ = (*reader)->info().mv_sigma_px();
    return frames;
  }
  static testing::TestDrive* drive_;
  static double sigma_px_;
};
testing::TestDrive* FrontEndTest::drive_ = nullptr;
double FrontEndTest::sigma_px_ = 0.0;

void ExpectSamePlanes(const std::vector<ExtractedPlane>& a, const std::vector<ExtractedPlane>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].track_id, b[k].track_id);
    EXPECT_EQ(a[k].tracked, b[k].tracked);
    EXPECT_EQ(a[k].correspondence_indices, b[k].correspondence_indices);
    EXPECT_EQ(a[k].H_earlier_from_later, b[k].H_earlier_from_later);
  }
}

TEST_F(FrontEndTest, ComputesWhatTheStagesChainedByHandCompute) {
  const std::vector<FrameRecord> frames = Frames();
  const Intrinsics& k = drive_->intrinsics;
  FrontEnd front_end(k, sigma_px_);
  SegmentMerger merger(k.width_px, k.height_px, sigma_px_, MergeOptions());
  PairMotionPriorTracker tracker;
  PlaneExtractor extractor{PlaneExtractionOptions()};
  int pairs = 0, seeded = 0, planes = 0;
  for (const FrameRecord& frame : frames) {
    std::optional<FrontEndStep> step = front_end.Push(frame);
    std::optional<AnchorPair> pair = merger.Push(frame);
    ASSERT_EQ(step.has_value(), pair.has_value());
    if (!pair.has_value()) continue;
    ++pairs;
    auto inf =
        ThresholdInfinity(pair->correspondences, k, InfinityOptions(), tracker.PriorFor(*pair));
    tracker.Record(*pair, inf.ok() ? &*inf : nullptr);
    ASSERT_TRUE(inf.ok() && step->infinity.ok());
    EXPECT_EQ(step->pair.later_index, pair->later_index);
    EXPECT_EQ(step->infinity->kept_indices, inf->kept_indices);
    EXPECT_EQ(step->infinity->motion_from_prior, inf->motion_from_prior);
    seeded += inf->motion_from_prior;
    auto extraction = extractor.Process(*pair, *inf, k);
    ASSERT_TRUE(extraction.ok() && step->extraction.ok());
    ExpectSamePlanes(step->extraction->planes, extraction->planes);
    planes += static_cast<int>(extraction->planes.size());
    EXPECT_GE(step->times.merge_ms, 0.0);
  }
  EXPECT_GE(pairs, 10);
  EXPECT_GT(seeded, 0) << "the motion prior was never used";
  EXPECT_GT(planes, 0);
}

TEST_F(FrontEndTest, PipelineStepsCarryTheFrontEndsPlanes) {
  const std::vector<FrameRecord> frames = Frames();
  FrontEnd front_end(drive_->intrinsics, sigma_px_);
  Pipeline pipeline(drive_->intrinsics, sigma_px_);
  std::map<PairMotionPath, int> paths;  // PipelineStep::motion_path -> pairs
  for (const FrameRecord& frame : frames) {
    std::optional<FrontEndStep> front = front_end.Push(frame);
    auto step = pipeline.Push(frame);
    ASSERT_TRUE(step.ok());
    ASSERT_EQ(front.has_value(), step->has_value());
    if (!front.has_value()) continue;
    ASSERT_TRUE(front->infinity.ok() && front->extraction.ok());
    EXPECT_EQ((*step)->kept, static_cast<int>(front->infinity->kept_indices.size()));
    EXPECT_EQ((*step)->motion_path, PairMotionPathOf(*front->infinity));
    ExpectSamePlanes((*step)->extracted, front->extraction->planes);
    ++paths[(*step)->motion_path];
  }
  // The first pair has no prior: the full fit; most others follow the prior.
  EXPECT_GE(paths[PairMotionPath::kFullFit], 1);
  EXPECT_GT(paths[PairMotionPath::kPrior], paths[PairMotionPath::kFullFit]);
  EXPECT_EQ(paths[PairMotionPath::kNone], 0);
}

TEST_F(FrontEndTest, ResetForgetsThePriorAndTheTracks) {
  const std::vector<FrameRecord> frames = Frames();
  FrontEnd front_end(drive_->intrinsics, sigma_px_);
  int pairs = 0;
  for (const FrameRecord& frame : frames) {
    std::optional<FrontEndStep> step = front_end.Push(frame);
    if (!step.has_value()) continue;
    if (++pairs == 6) front_end.Reset();  // the next frame starts a new segment
    if (pairs == 7) {
      ASSERT_TRUE(step->infinity.ok() && step->extraction.ok());
      EXPECT_FALSE(step->infinity->motion_from_prior);
      for (const ExtractedPlane& p : step->extraction->planes) EXPECT_FALSE(p.tracked);
    }
  }
  EXPECT_GE(pairs, 7);
}

// Pipeline::Finish's step is the pair an extended step handed back: counted
// once, as tracked or not, and no longer as extended.
// The texture gate on a flat sky (MergeOptions::min_mb_texture,
// docs/METHOD.md "MV merging"): a 10 fps highway drive at 1242x376 in H.264
// IPPP (the reporting drive whose first steps went sideways), whose sky is
// flat. Without the gate the encoder's sky vectors reach the pair motion and
// the plane extraction (two thirds of the correspondences, four fifths of
// the plane blocks); with it (the default) the sky gives almost none.
TEST(FrontEndTextureTest, AFlatSkyGivesNoCorrespondencesAndNoPlane) {
  SimulateOptions sim;
  sim.seed = 4002;
  sim.duration_s = 1.5;
  sim.fps = 10.0;
  sim.width_px = 1242;
  sim.height_px = 376;
  sim.hfov_deg = 80.7;
  sim.min_speed_mps = 70 / 3.6;
  sim.max_speed_mps = 100 / 3.6;
  sim.scene_kind = SceneKind::kHighway;
  sim.appearance_variety = true;
  sim.supersampling = 1;
  sim.sensor_noise = 0.15;
  sim.camera_height_min_m = sim.camera_height_max_m = 1.27;
  sim.pitch_down_min_deg = sim.pitch_down_max_deg = -1.6;
  auto encoder = EncoderPreset("h264-ippp", sim.fps);
  ASSERT_TRUE(encoder.ok()) << encoder.status().ToString();
  sim.encoder = *encoder;
  auto drive = testing::SimulateTestDrive("texture_sky", sim);
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  auto gt = LoadGroundTruth(drive->dir);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  struct Counts {
    int correspondences = 0, on_sky = 0, plane_mbs = 0, plane_mbs_on_sky = 0;
  };
  auto run = [&](double min_mb_texture) {
    auto reader = MvReader::Open(drive->video_path);
    EXPECT_TRUE(reader.ok()) << reader.status().ToString();
    FrontEndOptions options;
    options.merge.min_mb_texture = min_mb_texture;
    FrontEnd front(drive->intrinsics, (*reader)->info().mv_sigma_px(), options);
    const int cols = MbCount(drive->intrinsics.width_px);
    auto on_sky = [&](int64_t frame, int mb) {
      const Eigen::Vector2d c = MbCentreOfCell(mb % cols, mb / cols);
      return gt->LabelAt(static_cast<int>(frame), c.x(), c.y()) == kMbSky;
    };
    Counts n;
    FrameRecord f;
    while ((*reader)->Next(&f).ok()) {
      const auto step = front.Push(f);
      if (!step.has_value()) continue;
      for (const Correspondence& c : step->pair.correspondences) {
        ++n.correspondences;
        n.on_sky += on_sky(step->pair.later_index, c.mb_index);
      }
      if (!step->extraction.ok()) continue;
      for (const ExtractedPlane& plane : step->extraction->planes) {
        for (int mb : plane.mb_indices) {
          ++n.plane_mbs;
          n.plane_mbs_on_sky += on_sky(step->pair.later_index, mb);
        }
      }
    }
    std::printf(
        "min_mb_texture %g: %d correspondences, %d on the sky; %d plane blocks, %d on the sky\n",
        min_mb_texture, n.correspondences, n.on_sky, n.plane_mbs, n.plane_mbs_on_sky);
    return n;
  };
  const Counts off = run(0.0);
  const Counts on = run(MergeOptions{}.min_mb_texture);
  std::filesystem::remove_all(drive->dir);
  // Without the gate a large share of the correspondences is sky.
  ASSERT_GT(off.on_sky, off.correspondences / 4) << "the drive no longer shows a flat sky";
  EXPECT_GT(off.plane_mbs_on_sky, 0) << "without the gate the sky no longer makes planes";
  EXPECT_LT(on.on_sky, off.on_sky / 10);
  // Without the gate most plane blocks are sky; with it, at most a few at
  // the horizon (a block whose centre sees the sky and whose rest the far
  // scene).
  EXPECT_GT(off.plane_mbs_on_sky * 2, off.plane_mbs);
  EXPECT_LT(on.plane_mbs_on_sky * 10, on.plane_mbs);
  // The gate takes the sky, not the scene.
  EXPECT_GT(on.correspondences - on.on_sky, (off.correspondences - off.on_sky) * 9 / 10);
}

// The step of Pipeline::Finish replaces the extended step that handed its
// pair back (same anchors); a flushed chain (other anchors) is a pair of its
// own, and so is any finish step after a step that was not extended.
TEST(PipelineStepCountsTest, FinishReplacesTheExtendedStepAndAddsAFlushedChain) {
  auto step = [](int64_t earlier, int64_t later, bool tracking, bool extended) {
    PipelineStep s;
    s.earlier_index = earlier;
    s.later_index = later;
    s.tracking = tracking;
    s.extended = extended;
    return s;
  };
  PipelineStepCounts counts;
  counts.Add(step(0, 2, true, false));
  counts.Add(step(2, 4, false, true));
  EXPECT_EQ(counts.pairs, 2);
  EXPECT_EQ(counts.extended, 1);
  counts.AddFinish(step(2, 4, true, false));  // the handed-back pair, processed
  EXPECT_EQ(counts.pairs, 2);
  EXPECT_EQ(counts.tracked, 2);
  EXPECT_EQ(counts.extended, 0);

  PipelineStepCounts chained;
  chained.Add(step(0, 2, true, false));
  chained.Add(step(2, 4, true, false));
  chained.AddFinish(step(4, 5, true, false));  // the open chain, flushed
  EXPECT_EQ(chained.pairs, 3);
  EXPECT_EQ(chained.tracked, 3);
  EXPECT_EQ(chained.extended, 0);
}

}  // namespace
}  // namespace slapse
