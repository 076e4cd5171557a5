// Upload equals offline run: a simulated drive uploaded through a real
// loopback server with the real client gives exactly the trajectory and plane
// map that the offline Pipeline (`slapse run`) computes from the same file,
// and, written with the run's writers, the same TUM / KITTI / JSON bytes.
// Two sessions at once (different drives) each give their own drive's result.
#include <google/protobuf/util/time_util.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "api/convert.h"
#include "client/lib/client.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "core/pipeline/result_io.h"
#include "lab/codec/video_encoder.h"
#include "server/server.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::SlapseClient;
using server::SlapseServer;

// What `slapse run` computes for a file, with a session's default options.
struct OfflineResult {
  int64_t frames = 0;
  std::vector<TimedPose> trajectory;  // every posed frame (Pipeline::poses())
  std::vector<FramePose> poses;
  std::map<int, MapPlane> planes;
  bool metric = false;
};

StatusOr<OfflineResult> RunOffline(const testing::TestDrive& drive,
                                   const PipelineOptions& options = {}) {
  auto reader = MvReader::Open(drive.video_path);
  if (!reader.ok()) return reader.status();
  const StreamInfo& info = (*reader)->info();
  Intrinsics k = drive.intrinsics;
  k.width_px = info.width_px;
  k.height_px = info.height_px;
  Pipeline pipeline(k, info.mv_sigma_px(), options);
  OfflineResult out;
  FrameRecord frame;
  Status end;
  while ((end = (*reader)->Next(&frame)).ok()) {
    auto step = pipeline.Push(frame);
    if (!step.ok()) return step.status();
    ++out.frames;
  }
  if (end.code() != StatusCode::kOutOfRange) return end;
  pipeline.Finish();  // as `slapse run` does: a pair still handed back is posed
  out.poses = pipeline.poses();
  out.trajectory = TimedPosesOf(out.poses);
  out.planes = pipeline.plane_map();
  out.metric = pipeline.metric();
  return out;
}

// What a server returns for a session that ran to its end.
struct ServedResult {
  v1::Session session;
  v1::Trajectory trajectory;
  v1::PlaneMap plane_map;
  int extended_updates = 0;  // PoseUpdate.extended: a pair waiting for the next frame
};

// Creates an upload session (with `options` when given, else the server's
// defaults), uploads the drive, watches it to its final event and fetches
// the snapshots. Failures are gtest failures.
void Serve(SlapseClient& client, const testing::TestDrive& drive, ServedResult* out,
           const PipelineOptions* options = nullptr) {
  v1::Session request;
  request.mutable_upload();
  if (options != nullptr)
    *request.mutable_pipeline_options() = api::PipelineOptionsToProto(*options);
  *request.mutable_intrinsics() = api::IntrinsicsToProto(drive.intrinsics);
  auto created = client.CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string name = created->name();
  auto uploaded = client.UploadFile(name, drive.video_path);
  ASSERT_TRUE(uploaded.ok()) << uploaded.status().ToString();
  v1::Session::State last = v1::Session::STATE_UNSPECIFIED;
  int poses = 0;
  Status watched = client.Watch(name, 0, [&](const v1::SessionEvent& e) {
    if (e.has_state_change()) last = e.state_change().state();
    if (e.has_pose()) {
      // The latency stamps: the anchor frame was read before its step's event.
      ++poses;
      out->extended_updates += e.pose().extended();
      EXPECT_TRUE(e.pose().has_frame_received_time());
      EXPECT_TRUE(e.pose().has_emit_time());
      EXPECT_LE(e.pose().frame_received_time(), e.pose().emit_time());
    }
    return true;
  });
  ASSERT_TRUE(watched.ok()) << watched.ToString();
  EXPECT_EQ(last, v1::Session::FINISHED);
  EXPECT_GT(poses, 0);
  auto session = client.GetSession(name);
  auto trajectory = client.GetTrajectory(name);
  auto plane_map = client.GetPlaneMap(name);
  ASSERT_TRUE(session.ok()) << session.status().ToString();
  ASSERT_TRUE(trajectory.ok()) << trajectory.status().ToString();
  ASSERT_TRUE(plane_map.ok()) << plane_map.status().ToString();
  out->session = std::move(*session);
  out->trajectory = std::move(*trajectory);
  out->plane_map = std::move(*plane_map);
}

template <typename WriteFn>
std::string Written(WriteFn write) {
  std::ostringstream out;
  write(out);
  return out.str();
}

void ExpectSameResults(const OfflineResult& offline, const ServedResult& served) {
  constexpr double kTol = 1e-9;
  EXPECT_EQ(served.session.state(), v1::Session::FINISHED);
  EXPECT_EQ(served.session.stats().frames(), offline.frames);
  EXPECT_EQ(served.trajectory.metric(), offline.metric);
  ASSERT_EQ(served.trajectory.points_size(), static_cast<int>(offline.trajectory.size()));
  for (size_t i = 0; i < offline.trajectory.size(); ++i) {
    const TimedPose& o = offline.trajectory[i];
    const v1::Trajectory::Point& s = served.trajectory.points(static_cast<int>(i));
    const v1::Pose& p = s.world_from_cam();
    SCOPED_TRACE("pose " + std::to_string(i));
    EXPECT_EQ(s.anchor_index(), o.index);
    EXPECT_NEAR(s.timestamp_s(), o.timestamp_s, kTol);
    EXPECT_NEAR(p.tx(), o.world_from_cam.translation.x(), kTol);
    EXPECT_NEAR(p.ty(), o.world_from_cam.translation.y(), kTol);
    EXPECT_NEAR(p.tz(), o.world_from_cam.translation.z(), kTol);
    EXPECT_NEAR(p.qx(), o.world_from_cam.rotation.x(), kTol);
    EXPECT_NEAR(p.qy(), o.world_from_cam.rotation.y(), kTol);
    EXPECT_NEAR(p.qz(), o.world_from_cam.rotation.z(), kTol);
    EXPECT_NEAR(p.qw(), o.world_from_cam.rotation.w(), kTol);
  }
  EXPECT_EQ(served.session.stats().planes(), static_cast<int>(offline.planes.size()));
  ASSERT_EQ(served.plane_map.planes_size(), static_cast<int>(offline.planes.size()));
  for (const v1::PlaneMap::Plane& s : served.plane_map.planes()) {
    SCOPED_TRACE("plane " + std::to_string(s.track_id()));
    auto it = offline.planes.find(s.track_id());
    ASSERT_NE(it, offline.planes.end());
    const MapPlane& o = it->second;
    EXPECT_NEAR(s.normal_world().x(), o.normal_world.x(), kTol);
    EXPECT_NEAR(s.normal_world().y(), o.normal_world.y(), kTol);
    EXPECT_NEAR(s.normal_world().z(), o.normal_world.z(), kTol);
    EXPECT_NEAR(s.distance(), o.distance_m, kTol);
    EXPECT_NEAR(s.first_seen_s(), o.first_seen_s, kTol);
    EXPECT_NEAR(s.last_seen_s(), o.last_seen_s, kTol);
    EXPECT_EQ(s.observations(), o.observations);
  }

  // `slapse export` writes the served results with the run's writers: the
  // files are byte for byte those of `slapse run`.
  const auto served_traj = api::TrajectoryFromProto(served.trajectory);
  EXPECT_EQ(Written([&](std::ostream& o) { WriteTrajectoryTum(served_traj, o); }),
            Written([&](std::ostream& o) { WriteTrajectoryTum(offline.trajectory, o); }));
  EXPECT_EQ(Written([&](std::ostream& o) { WriteTrajectoryKitti(served_traj, o); }),
            Written([&](std::ostream& o) { WriteTrajectoryKitti(offline.trajectory, o); }));
  EXPECT_EQ(Written([&](std::ostream& o) {
              WritePoseQualityCsv(api::FramePosesFromProto(served.trajectory), o);
            }),
            Written([&](std::ostream& o) { WritePoseQualityCsv(offline.poses, o); }));
  ResultJsonOptions json;
  json.seen_at_frames = false;  // not kept by a server
  EXPECT_EQ(
      Written([&](std::ostream& o) {
        WriteResultJson(api::PlaneMapFromProto(served.plane_map), served.plane_map.metric(), json,
                        o);
      }),
      Written([&](std::ostream& o) { WriteResultJson(offline.planes, offline.metric, json, o); }));
}

class ServiceE2eTest : public ::testing::Test {
 protected:
  // Two short drives (different seeds, so different streets and paths) and
  // their offline results, shared by the tests.
  static void SetUpTestSuite() {
    for (uint64_t seed : {21, 22}) {
      auto drive =
          testing::SimulateTestDrive("service_e2e", testing::SmallMpeg2DriveOptions(seed, 4.0));
      ASSERT_TRUE(drive.ok()) << drive.status().ToString();
      auto offline = RunOffline(*drive);
      ASSERT_TRUE(offline.ok()) << offline.status().ToString();
      drives_.push_back(std::move(*drive));
      offline_.push_back(std::move(*offline));
    }
  }

  static void TearDownTestSuite() {
    for (const testing::TestDrive& d : drives_) std::filesystem::remove_all(d.dir);
  }

  void SetUp() override {
    ASSERT_EQ(drives_.size(), 2u);
    // Not vacuous: each drive tracks and maps, and the two results differ.
    for (const OfflineResult& o : offline_) {
      ASSERT_GE(o.trajectory.size(), 10u);
      ASSERT_GE(o.planes.size(), 1u);
    }
    ASSERT_GT((offline_[0].trajectory.back().world_from_cam.translation -
               offline_[1].trajectory.back().world_from_cam.translation)
                  .norm(),
              1e-3);
    server::ServerOptions o;
    o.address = "127.0.0.1";
    o.port = 0;
    o.sessions.max_sessions = 2;
    o.sessions.upload_buffer_bytes = 256 << 10;  // the uploads feel backpressure
    o.sessions.final_poses_in_memory = 8;        // the pipelines forget: results from the store
    o.shutdown_grace_s = 1;
    auto server = SlapseServer::Start(o);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    client::ClientOptions c;
    c.rpc_timeout_s = 10;
    c.upload_timeout_s = 50;
    c.watch_timeout_s = 50;
    c.upload_chunk_bytes = 64 << 10;
    client_ = SlapseClient::Connect("127.0.0.1:" + std::to_string(server_->port()), c);
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  static std::vector<testing::TestDrive> drives_;
  static std::vector<OfflineResult> offline_;
  std::unique_ptr<SlapseServer> server_;
  std::unique_ptr<SlapseClient> client_;
};

std::vector<testing::TestDrive> ServiceE2eTest::drives_;
std::vector<OfflineResult> ServiceE2eTest::offline_;

TEST_F(ServiceE2eTest, UploadEqualsOfflineRun) {
  ServedResult served;
  ASSERT_NO_FATAL_FAILURE(Serve(*client_, drives_[0], &served));
  ExpectSameResults(offline_[0], served);
}

TEST_F(ServiceE2eTest, ConcurrentSessionsStayIsolated) {
  ServedResult served[2];
  std::thread other([&] { Serve(*client_, drives_[1], &served[1]); });
  Serve(*client_, drives_[0], &served[0]);
  other.join();
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_NE(served[0].session.name(), served[1].session.name());
  {
    SCOPED_TRACE("session of drive 0");
    ExpectSameResults(offline_[0], served[0]);
  }
  {
    SCOPED_TRACE("session of drive 1");
    ExpectSameResults(offline_[1], served[1]);
  }
}

// A car park at 3-4 m/s, 60 fps, H.264 IPPP. With the defaults, P frames are
// chained into 3-frame pairs (MergeOptions::min_pair_span_s); with one-frame
// pairs, those too short for their parallax wait for the next frame
// (PipelineOptions::track_max_baseline_s). Either way the session's result
// equals the offline run to the last frame: a chain still open, or a pair
// still held back, when the upload ends is processed at the connection's end
// (Pipeline::Finish) and its frames' poses are sent.
TEST_F(ServiceE2eTest, SlowIpppDriveIsPosedToItsLastFrameAsOffline) {
  SimulateOptions o = testing::SmallMpeg2DriveOptions(2, 2.0);
  o.scene_kind = SceneKind::kPlaza;
  o.fps = 60.0;
  o.min_speed_mps = 3.0;
  o.max_speed_mps = 4.0;
  auto encoder = EncoderPreset("h264-ippp", o.fps);
  ASSERT_TRUE(encoder.ok()) << encoder.status().ToString();
  o.encoder = *encoder;
  auto drive = testing::SimulateTestDrive("service_e2e_slow", o);
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  PipelineOptions one_frame_pairs;
  one_frame_pairs.merge.min_pair_span_s = 0.0;
  for (const PipelineOptions* options : {static_cast<const PipelineOptions*>(nullptr),
                                         static_cast<const PipelineOptions*>(&one_frame_pairs)}) {
    SCOPED_TRACE(options == nullptr ? "defaults: chained pairs" : "one-frame pairs");
    auto offline = RunOffline(*drive, options == nullptr ? PipelineOptions{} : *options);
    ASSERT_TRUE(offline.ok()) << offline.status().ToString();
    // Not vacuous: every frame is posed (so the last pair's frames are too),
    // and the drive's 120 frames do not end on a whole chain.
    EXPECT_EQ(static_cast<int64_t>(offline->trajectory.size()), offline->frames);
    EXPECT_NE((offline->frames - 1) % 3, 0);
    ServedResult served;
    ASSERT_NO_FATAL_FAILURE(Serve(*client_, *drive, &served, options));
    ExpectSameResults(*offline, served);
    if (options != nullptr) EXPECT_GT(served.extended_updates, 0);
  }
  std::filesystem::remove_all(drive->dir);
}

}  // namespace
}  // namespace slapse
