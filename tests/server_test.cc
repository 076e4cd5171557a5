// The slapse service end to end: a real server on 127.0.0.1 (ephemeral port)
// in-process, the real client library, streams made by the real encoders.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/create_channel.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/byte_buffer.h>

#include "api/convert.h"
#include "client/lib/client.h"
#include "core/pipeline/result_io.h"
#include "lab/sim/simulate.h"
#include "server/server.h"
#include "server/upload_queue.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::ClientOptions;
using client::SlapseClient;
using server::ServerOptions;
using server::SlapseServer;
using testing::FfmpegProcess;
using testing::FreeRtpPort;
using testing::Mpeg2RtpSdp;
using testing::PortOf;
using testing::TestClientOptions;
using testing::WaitForLocalPort;

StatusOr<std::unique_ptr<SlapseServer>> StartServer(int max_sessions, size_t ring = 4096) {
  ServerOptions o;
  o.address = "127.0.0.1";
  o.port = 0;
  o.sessions.max_sessions = max_sessions;
  o.sessions.event_ring_capacity = ring;
  o.sessions.upload_buffer_bytes = 256 << 10;  // small: the upload feels backpressure
  o.shutdown_grace_s = 1;
  return SlapseServer::Start(o);
}

class ServerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::string(testing::MakeTempDir("server_test"));
    auto drive =
        testing::SimulateTestDrive("server_test_drive", testing::SmallMpeg2DriveOptions(3, 2.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    drive_ = new std::string(testing::ReadFileBytes(drive->video_path));
    drive_path_ = new std::string(drive->video_path);
    intrinsics_ = new Intrinsics(drive->intrinsics);
  }
  static void TearDownTestSuite() {
    delete dir_;
    delete drive_;
    delete drive_path_;
    delete intrinsics_;
  }

  void SetUp() override {
    ASSERT_NE(drive_, nullptr);
    auto server = StartServer(3);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    client_ =
        SlapseClient::Connect("127.0.0.1:" + std::to_string(server_->port()), TestClientOptions());
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  static v1::Session UploadRequest() {
    v1::Session s;
    s.mutable_upload();
    v1::Intrinsics* k = s.mutable_intrinsics();
    k->set_fx_px(intrinsics_->fx_px);
    k->set_fy_px(intrinsics_->fy_px);
    k->set_cx_px(intrinsics_->cx_px);
    k->set_cy_px(intrinsics_->cy_px);
    return s;
  }

  // Watches `name` after `after` to the end; returns the events.
  std::vector<v1::SessionEvent> WatchAll(const std::string& name, uint64_t after, Status* end) {
    std::vector<v1::SessionEvent> events;
    *end = client_->Watch(name, after, [&](const v1::SessionEvent& e) {
      events.push_back(e);
      return true;
    });
    return events;
  }

  static std::string* dir_;
  static std::string* drive_;
  static std::string* drive_path_;
  static Intrinsics* intrinsics_;
  std::unique_ptr<SlapseServer> server_;
  std::unique_ptr<SlapseClient> client_;
};

std::string* ServerTest::dir_ = nullptr;
std::string* ServerTest::drive_ = nullptr;
std::string* ServerTest::drive_path_ = nullptr;
Intrinsics* ServerTest::intrinsics_ = nullptr;

TEST_F(ServerTest, UploadAndWatchToTheEndThenResume) {
  auto created = client_->CreateSession(UploadRequest());
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string name = created->name();
  EXPECT_EQ(created->state(), v1::Session::CREATED);

  // Watch live while the upload runs.
  std::vector<v1::SessionEvent> events;
  Status watch_end;
  std::thread watcher([&] { events = WatchAll(name, 0, &watch_end); });
  auto uploaded = client_->UploadBytes(name, *drive_);
  watcher.join();
  ASSERT_TRUE(uploaded.ok()) << uploaded.status().ToString();
  ASSERT_TRUE(watch_end.ok()) << watch_end.ToString();

  ASSERT_GE(events.size(), 3u);
  int poses = 0;
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_EQ(events[i].sequence(), i + 1) << "sequences are 1, 2, 3, ...";
    if (events[i].has_pose()) {
      ++poses;
      EXPECT_EQ(events[i].pose().sequence(), events[i].sequence());
    }
  }
  EXPECT_GT(poses, 5);
  EXPECT_EQ(events.front().state_change().state(), v1::Session::CREATED);
  ASSERT_TRUE(events.back().has_state_change());
  EXPECT_EQ(events.back().state_change().state(), v1::Session::FINISHED);

  auto got = client_->GetSession(name);
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FINISHED);
  EXPECT_EQ(got->stats().frames(), 60);
  EXPECT_EQ(got->stats().anchor_pairs(), poses);
  EXPECT_GT(got->stats().fps(), 0);
  EXPECT_EQ(got->last_sequence(), events.size());

  // Resume from the middle: exactly the rest, nothing lost or repeated.
  const uint64_t middle = events.size() / 2;
  Status resume_end;
  std::vector<v1::SessionEvent> rest = WatchAll(name, middle, &resume_end);
  ASSERT_TRUE(resume_end.ok()) << resume_end.ToString();
  ASSERT_EQ(rest.size(), events.size() - middle);
  for (size_t i = 0; i < rest.size(); ++i) {
    EXPECT_EQ(rest[i].SerializeAsString(), events[middle + i].SerializeAsString());
  }

  auto traj = client_->GetTrajectory(name);
  ASSERT_TRUE(traj.ok()) << traj.status().ToString();
  EXPECT_EQ(traj->last_sequence(), events.size());
  auto list = client_->ListSessions(0, "", v1::Session::FINISHED);
  ASSERT_TRUE(list.ok()) << list.status().ToString();
  ASSERT_EQ(list->sessions_size(), 1);
  EXPECT_EQ(list->sessions(0).name(), name);
}

int CountPoses(const std::vector<v1::SessionEvent>& events) {
  int poses = 0;
  for (const auto& e : events) poses += e.has_pose();
  return poses;
}

// The camera publishes with ANNOUNCE / RECORD over TCP; TEARDOWN at its end
// finishes the session.
TEST_F(ServerTest, RtspPushStreamsPosesToFinished) {
  v1::Session request = UploadRequest();
  request.mutable_rtsp_push()->set_path("cam1");
  request.mutable_rtsp_push()->set_start_timeout_ms(10000);
  request.mutable_rtsp_push()->set_receive_timeout_ms(3000);
  auto created = client_->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string url = testing::PublishUrl(*created);
  const std::string& ingest = created->ingest_url();
  ASSERT_EQ(ingest, "rtsp://127.0.0.1:" + std::to_string(server_->sessions().rtsp_port()) + "/" +
                        created->name() + "/cam1");
  Status watch_end;
  std::vector<v1::SessionEvent> events;
  std::thread watcher([&] { events = WatchAll(created->name(), 0, &watch_end); });
  ASSERT_TRUE(WaitForLocalPort("tcp", PortOf(url), std::chrono::seconds(5)));
  {
    FfmpegProcess camera(
        {"-re", "-i", *drive_path_, "-c", "copy", "-f", "rtsp", "-rtsp_transport", "tcp", url});
    ASSERT_TRUE(camera.started());
    EXPECT_EQ(camera.Wait(std::chrono::seconds(15)), 0);
  }
  watcher.join();  // bounded by the client's watch deadline
  ASSERT_TRUE(watch_end.ok()) << watch_end.ToString();
  EXPECT_GT(CountPoses(events), 5);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state_change().state(), v1::Session::FINISHED)
      << events.back().state_change().message();
  EXPECT_EQ(
      events.back().state_change().message().find("the publisher ended the stream (TEARDOWN)"), 0u)
      << events.back().state_change().message();
  auto got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_GT(got->stats().frames(), 40);
}

// RTP has no end marker: the session finishes after receive_timeout_ms of silence.
TEST_F(ServerTest, RtpSdpStreamsPosesUntilTheReceiveTimeout) {
  const int port = FreeRtpPort();
  ASSERT_GT(port, 0);
  v1::Session request = UploadRequest();
  request.mutable_rtp_sdp()->set_sdp(Mpeg2RtpSdp(port));
  request.mutable_rtp_sdp()->set_start_timeout_ms(10000);
  request.mutable_rtp_sdp()->set_receive_timeout_ms(1000);
  auto created = client_->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  EXPECT_TRUE(created->ingest_url().empty());
  Status watch_end;
  std::vector<v1::SessionEvent> events;
  std::thread watcher([&] { events = WatchAll(created->name(), 0, &watch_end); });
  // Send only once the receiver has bound its port: UDP drops what comes early.
  ASSERT_TRUE(WaitForLocalPort("udp", port, std::chrono::seconds(5)));
  {
    FfmpegProcess camera({"-re", "-i", *drive_path_, "-c", "copy", "-f", "rtp",
                          "rtp://127.0.0.1:" + std::to_string(port)});
    ASSERT_TRUE(camera.started());
    EXPECT_EQ(camera.Wait(std::chrono::seconds(15)), 0);
  }
  watcher.join();
  ASSERT_TRUE(watch_end.ok()) << watch_end.ToString();
  EXPECT_GT(CountPoses(events), 5);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state_change().state(), v1::Session::FINISHED);
  EXPECT_NE(events.back().state_change().message().find("receive_timeout_ms=1000"),
            std::string::npos)
      << events.back().state_change().message();
}

TEST_F(ServerTest, BadNetworkSourcesAreInvalidArgument) {
  v1::Session request = UploadRequest();
  for (const std::string& sdp : {std::string(), std::string("hello"),
                                 std::string("v=0\nc=IN IP4 127.0.0.1\nm=audio 5004 RTP/AVP 0\n"),
                                 std::string("v=0\nm=video 5004 RTP/AVP 32\n"),
                                 std::string("v=0\nc=IN IP4 127.0.0.1\nm=video x RTP/AVP 32\n")}) {
    request.mutable_rtp_sdp()->set_sdp(sdp);
    EXPECT_EQ(client_->CreateSession(request).status().code(), StatusCode::kInvalidArgument) << sdp;
  }
  request.mutable_rtp_sdp()->set_sdp(Mpeg2RtpSdp(5004));
  request.mutable_rtp_sdp()->set_receive_timeout_ms(-1);
  EXPECT_EQ(client_->CreateSession(request).status().code(), StatusCode::kInvalidArgument);
  for (const std::string path : {"", "/cam", "a b", "cam?x=1"}) {
    request.mutable_rtsp_push()->set_path(path);
    EXPECT_EQ(client_->CreateSession(request).status().code(), StatusCode::kInvalidArgument)
        << path;
  }
}

// Starts a camera publishing to a new RTSP push session and waits until the
// session has decoded 10 frames. Returns the session name.
std::string StartRtspCamera(SlapseClient* client, v1::Session request, const std::string& drive,
                            std::unique_ptr<FfmpegProcess>* camera) {
  auto created = client->CreateSession(request);
  EXPECT_TRUE(created.ok()) << created.status().ToString();
  if (!created.ok()) return "";
  const std::string url = testing::PublishUrl(*created);
  EXPECT_TRUE(WaitForLocalPort("tcp", PortOf(url), std::chrono::seconds(5)));
  *camera = std::make_unique<FfmpegProcess>(std::vector<std::string>{
      "-re", "-i", drive, "-c", "copy", "-f", "rtsp", "-rtsp_transport", "tcp", url});
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  int64_t frames = 0;
  while (frames < 10 && std::chrono::steady_clock::now() < deadline) {
    auto got = client->GetSession(created->name());
    if (!got.ok()) break;
    frames = got->stats().frames();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_GE(frames, 10);
  return created->name();
}

// A camera that stops mid-stream ends the session visibly and soon, never a
// hang: frozen (connection open, silent) it FAILs with UNAVAILABLE after
// receive_timeout_ms; killed (connection closed without TEARDOWN) it FAILs at
// once with UNAVAILABLE saying the camera was lost.
TEST_F(ServerTest, RtspCameraThatStopsMidStreamEndsTheSession) {
  v1::Session request = UploadRequest();
  request.mutable_rtsp_push()->set_path("cam2");
  request.mutable_rtsp_push()->set_start_timeout_ms(10000);
  request.mutable_rtsp_push()->set_receive_timeout_ms(1000);

  std::unique_ptr<FfmpegProcess> camera;
  std::string name = StartRtspCamera(client_.get(), request, *drive_path_, &camera);
  ASSERT_FALSE(name.empty());
  camera->Freeze();
  auto t0 = std::chrono::steady_clock::now();
  Status watch_end;
  std::vector<v1::SessionEvent> events = WatchAll(name, 0, &watch_end);
  ASSERT_TRUE(watch_end.ok()) << watch_end.ToString();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(4));
  EXPECT_GT(CountPoses(events), 0);
  auto got = client_->GetSession(name);
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FAILED);
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kUnavailable))
      << got->error().message();
  EXPECT_NE(got->error().message().find("receive_timeout_ms=1000"), std::string::npos);
  camera->Kill();

  name = StartRtspCamera(client_.get(), request, *drive_path_, &camera);
  ASSERT_FALSE(name.empty());
  camera->Kill();
  t0 = std::chrono::steady_clock::now();
  events = WatchAll(name, 0, &watch_end);
  ASSERT_TRUE(watch_end.ok()) << watch_end.ToString();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(4));
  ASSERT_FALSE(events.empty());
  const v1::StateChange& last = events.back().state_change();
  EXPECT_EQ(last.state(), v1::Session::FAILED) << last.message();
  EXPECT_NE(last.message().find("lost without a TEARDOWN"), std::string::npos) << last.message();
}

// No publisher: start_timeout_ms fails the session; StopSession aborts the wait.
TEST_F(ServerTest, RtspListenerWithoutPublisherTimesOutOrStops) {
  v1::Session request = UploadRequest();
  request.mutable_rtsp_push()->set_path("nobody");
  request.mutable_rtsp_push()->set_start_timeout_ms(300);
  auto created = client_->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  Status end;
  WatchAll(created->name(), 0, &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  auto got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->state(), v1::Session::FAILED);
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kDeadlineExceeded));

  request.mutable_rtsp_push()->set_start_timeout_ms(60000);
  auto waiting = client_->CreateSession(request);
  ASSERT_TRUE(waiting.ok()) << waiting.status().ToString();
  ASSERT_TRUE(WaitForLocalPort("tcp", PortOf(waiting->ingest_url()), std::chrono::seconds(5)));
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(client_->StopSession(waiting->name()).ok());
  WatchAll(waiting->name(), 0, &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  EXPECT_EQ(client_->GetSession(waiting->name())->state(), v1::Session::STOPPED);
  // The worker is free again: the server shuts down promptly.
  server_->Shutdown();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(3));
}

TEST_F(ServerTest, UnknownSessionIsNotFound) {
  EXPECT_EQ(client_->GetSession("sessions/12345").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(client_->DeleteSession("sessions/12345").code(), StatusCode::kNotFound);
  EXPECT_EQ(client_->UploadBytes("sessions/12345", "abc").status().code(), StatusCode::kNotFound);
  Status end;
  WatchAll("sessions/12345", 0, &end);
  EXPECT_EQ(end.code(), StatusCode::kNotFound);
  EXPECT_EQ(client_->GetSession("nonsense").status().code(), StatusCode::kInvalidArgument);
}

TEST_F(ServerTest, BadIntrinsicsAreInvalidArgument) {
  v1::Session request = UploadRequest();
  request.mutable_intrinsics()->set_fx_px(-1);
  auto created = client_->CreateSession(request);
  EXPECT_EQ(created.status().code(), StatusCode::kInvalidArgument);
}

// With re-encoding refused (StreamOptions.reencode = false, `create
// --no-reencode`), a codec without vectors FAILs the session.
TEST_F(ServerTest, HevcUploadFailsWithFailedPreconditionAndServerKeepsServing) {
  const std::string hevc = *dir_ + "/x.mkv";
  ASSERT_EQ(testing::RunCommand("ffmpeg -nostdin -loglevel error -y -f lavfi -i "
                                "testsrc=size=160x120:rate=10 -frames:v 5 -c:v libx265 "
                                "-x265-params log-level=error " +
                                hevc),
            0);
  v1::Session refusing = UploadRequest();
  refusing.mutable_stream_options()->set_reencode(false);
  auto created = client_->CreateSession(refusing);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  auto uploaded = client_->UploadBytes(created->name(), testing::ReadFileBytes(hevc));
  // The upload either completes before the session fails or reports its error.
  if (!uploaded.ok()) {
    EXPECT_EQ(uploaded.status().code(), StatusCode::kFailedPrecondition);
  }
  Status end;
  std::vector<v1::SessionEvent> events = WatchAll(created->name(), 0, &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state_change().state(), v1::Session::FAILED);
  auto got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FAILED);
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kFailedPrecondition));
  EXPECT_NE(got->error().message().find("hevc"), std::string::npos) << got->error().message();

  // Another session on the same server still runs to the end.
  auto next = client_->CreateSession(UploadRequest());
  ASSERT_TRUE(next.ok()) << next.status().ToString();
  ASSERT_TRUE(client_->UploadBytes(next->name(), *drive_).ok());
  WatchAll(next->name(), 0, &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  auto done = client_->GetSession(next->name());
  ASSERT_TRUE(done.ok());
  EXPECT_EQ(done->state(), v1::Session::FINISHED);
}

// By default a codec without vectors is re-encoded in-process (issue 13): the
// drive as HEVC (ffmpeg's libx265, the camera) tracks to FINISHED, and the
// session says "re-encoded from hevc" with its cost.
TEST_F(ServerTest, HevcUploadIsReencodedAndTracks) {
  const std::string hevc = *dir_ + "/drive_hevc.ts";
  ASSERT_EQ(testing::RunCommand(
                "ffmpeg -nostdin -loglevel error -y -i " + *drive_path_ +
                " -c:v libx265 -preset ultrafast -x265-params log-level=error:keyint=30 " + hevc),
            0);
  auto created = client_->CreateSession(UploadRequest());
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  ASSERT_TRUE(client_->UploadBytes(created->name(), testing::ReadFileBytes(hevc)).ok());
  Status end;
  std::vector<v1::SessionEvent> events = WatchAll(created->name(), 0, &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  EXPECT_GT(CountPoses(events), 5);
  auto got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FINISHED) << got->state_message();
  const v1::StreamReport& r = got->stream_report();
  EXPECT_EQ(r.codec(), "hevc");
  EXPECT_TRUE(r.reencoded());
  EXPECT_EQ(r.reencoded_to(), "mpeg2video");
  EXPECT_EQ(r.frames(), 60);
  EXPECT_GT(r.reencode_cpu_s(), 0.0);
  EXPECT_GT(r.decode_cpu_s(), 0.0);
  EXPECT_EQ(r.notes_size(), 0);
}

TEST_F(ServerTest, OverCapacityIsResourceExhausted) {
  auto small = StartServer(1);
  ASSERT_TRUE(small.ok()) << small.status().ToString();
  auto c =
      SlapseClient::Connect("127.0.0.1:" + std::to_string((*small)->port()), TestClientOptions());
  auto first = c->CreateSession(UploadRequest());
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  auto second = c->CreateSession(UploadRequest());
  EXPECT_EQ(second.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(second.status().message().find("capacity"), std::string::npos);
  // Stopping the first frees its slot.
  auto stopped = c->StopSession(first->name());
  ASSERT_TRUE(stopped.ok()) << stopped.status().ToString();
  EXPECT_EQ(stopped->state(), v1::Session::STOPPED);
  EXPECT_TRUE(c->CreateSession(UploadRequest()).ok());
  // Graceful shutdown with a session waiting for its upload does not hang.
  (*small)->Shutdown();
}

StatusOr<std::unique_ptr<SlapseServer>> StartServerWithRetention(int64_t ttl_s,
                                                                 int64_t max_store_bytes = 0) {
  ServerOptions o;
  o.address = "127.0.0.1";
  o.port = 0;
  o.sessions.event_ring_capacity = 4;
  o.sessions.retention_ttl_s = ttl_s;
  o.sessions.retention_max_store_bytes = max_store_bytes;
  o.shutdown_grace_s = 1;
  return SlapseServer::Start(o);
}

// Polls (bounded) until `name` is no longer CREATED / RUNNING.
v1::Session WaitForEnd(SlapseClient& c, const std::string& name) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  v1::Session s;
  do {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    auto got = c.GetSession(name);
    if (!got.ok()) break;
    s = *got;
  } while ((s.state() == v1::Session::RUNNING || s.state() == v1::Session::CREATED) &&
           std::chrono::steady_clock::now() < deadline);
  return s;
}

// A ring of 4 events: a watch from the start reads the older ones from the
// store (server/store.h), every event once and in order.
TEST_F(ServerTest, CursorOlderThanTheRingReadsFromTheStore) {
  auto small = StartServer(1, /*ring=*/4);
  ASSERT_TRUE(small.ok()) << small.status().ToString();
  auto c =
      SlapseClient::Connect("127.0.0.1:" + std::to_string((*small)->port()), TestClientOptions());
  auto created = c->CreateSession(UploadRequest());
  ASSERT_TRUE(created.ok());
  ASSERT_TRUE(c->UploadBytes(created->name(), *drive_).ok());
  const v1::Session s = WaitForEnd(*c, created->name());
  ASSERT_EQ(s.state(), v1::Session::FINISHED);
  ASSERT_GT(s.last_sequence(), 20u);  // far beyond the ring
  std::vector<v1::SessionEvent> events;
  Status end = c->Watch(created->name(), 0, [&](const v1::SessionEvent& e) {
    events.push_back(e);
    return true;
  });
  ASSERT_TRUE(end.ok()) << end.ToString();
  ASSERT_EQ(events.size(), s.last_sequence());
  for (size_t i = 0; i < events.size(); ++i) EXPECT_EQ(events[i].sequence(), i + 1);
  EXPECT_EQ(events.front().state_change().state(), v1::Session::CREATED);
  EXPECT_EQ(events.back().state_change().state(), v1::Session::FINISHED);
  // From the middle: exactly the rest.
  std::vector<v1::SessionEvent> rest;
  end = c->Watch(created->name(), 7, [&](const v1::SessionEvent& e) {
    rest.push_back(e);
    return true;
  });
  ASSERT_TRUE(end.ok()) << end.ToString();
  ASSERT_EQ(rest.size(), events.size() - 7);
  for (size_t i = 0; i < rest.size(); ++i) {
    EXPECT_EQ(rest[i].SerializeAsString(), events[7 + i].SerializeAsString());
  }
}

// Pages of 7 (and time ranges) give exactly the unpaged trajectory.
TEST_F(ServerTest, PagedTrajectoryEqualsTheWholeOne) {
  auto created = client_->CreateSession(UploadRequest());
  ASSERT_TRUE(created.ok());
  ASSERT_TRUE(client_->UploadBytes(created->name(), *drive_).ok());
  ASSERT_EQ(WaitForEnd(*client_, created->name()).state(), v1::Session::FINISHED);
  v1::GetTrajectoryRequest whole;
  whole.set_name(created->name());
  auto all = client_->GetTrajectoryPage(whole);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  ASSERT_GT(all->points_size(), 10);
  EXPECT_TRUE(all->next_page_token().empty());
  v1::GetTrajectoryRequest paged = whole;
  paged.set_page_size(7);
  std::vector<v1::Trajectory::Point> pages;
  int requests = 0;
  do {
    auto page = client_->GetTrajectoryPage(paged);
    ASSERT_TRUE(page.ok()) << page.status().ToString();
    ASSERT_LE(page->points_size(), 7);
    for (const auto& p : page->points()) pages.push_back(p);
    paged.set_page_token(page->next_page_token());
    ++requests;
  } while (!paged.page_token().empty() && requests < 1000);
  ASSERT_EQ(static_cast<int>(pages.size()), all->points_size());
  EXPECT_EQ(requests, (all->points_size() + 6) / 7);
  for (size_t i = 0; i < pages.size(); ++i) {
    EXPECT_EQ(pages[i].SerializeAsString(), all->points(static_cast<int>(i)).SerializeAsString());
  }
  // A time range: the points with start <= t < end, nothing else.
  const double start_s = all->points(3).timestamp_s();
  const double end_s = all->points(8).timestamp_s();
  v1::GetTrajectoryRequest range = whole;
  range.set_start_time_s(start_s);
  range.set_end_time_s(end_s);
  auto part = client_->GetTrajectoryPage(range);
  ASSERT_TRUE(part.ok()) << part.status().ToString();
  ASSERT_EQ(part->points_size(), 5);
  EXPECT_EQ(part->points(0).SerializeAsString(), all->points(3).SerializeAsString());
  // The client library in pages of 7: GetTrajectory gives the unpaged answer
  // (name, last_sequence and all), and ForEachTrajectoryPage's pages written
  // one at a time (what `slapse export` does) give the unpaged file's bytes.
  ClientOptions small_pages = TestClientOptions();
  small_pages.page_size = 7;
  auto pager = SlapseClient::Connect("127.0.0.1:" + std::to_string(server_->port()), small_pages);
  auto gathered = pager->GetTrajectory(created->name());
  ASSERT_TRUE(gathered.ok()) << gathered.status().ToString();
  EXPECT_EQ(gathered->SerializeAsString(), all->SerializeAsString());
  std::ostringstream streamed;
  WriteTrajectoryTumHeader(streamed);
  int calls = 0;
  ASSERT_TRUE(pager
                  ->ForEachTrajectoryPage(created->name(),
                                          [&](const v1::Trajectory& page) {
                                            EXPECT_LE(page.points_size(), 7);
                                            WriteTrajectoryTumRows(api::TrajectoryFromProto(page),
                                                                   streamed);
                                            return ++calls < 1000;
                                          })
                  .ok());
  EXPECT_EQ(calls, (all->points_size() + 6) / 7);
  std::ostringstream whole_file;
  WriteTrajectoryTum(api::TrajectoryFromProto(*all), whole_file);
  EXPECT_EQ(streamed.str(), whole_file.str());
  // A caller that stops early gets CANCELLED after its page.
  calls = 0;
  EXPECT_EQ(pager
                ->ForEachTrajectoryPage(created->name(),
                                        [&](const v1::Trajectory&) { return ++calls < 2; })
                .code(),
            StatusCode::kCancelled);
  EXPECT_EQ(calls, 2);
  // Bad paging is a precise error.
  v1::GetTrajectoryRequest bad = whole;
  bad.set_page_token("garbage");
  EXPECT_EQ(client_->GetTrajectoryPage(bad).status().code(), StatusCode::kInvalidArgument);
  bad = whole;
  bad.set_page_size(-1);
  EXPECT_EQ(client_->GetTrajectoryPage(bad).status().code(), StatusCode::kInvalidArgument);
  bad = whole;
  bad.set_start_time_s(5);
  bad.set_end_time_s(1);
  EXPECT_EQ(client_->GetTrajectoryPage(bad).status().code(), StatusCode::kInvalidArgument);
}

// --retention-ttl-s: a finished session's results go, the session says so
// (EXPIRED, with a StateChange), a running one alongside is untouched.
TEST_F(ServerTest, RetentionExpiresFinishedSessionsVisibly) {
  auto server = StartServerWithRetention(1);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  auto c =
      SlapseClient::Connect("127.0.0.1:" + std::to_string((*server)->port()), TestClientOptions());
  auto finished = c->CreateSession(UploadRequest());
  auto waiting = c->CreateSession(UploadRequest());  // CREATED: active, never expires
  ASSERT_TRUE(finished.ok() && waiting.ok());
  ASSERT_TRUE(c->UploadBytes(finished->name(), *drive_).ok());
  // FINISHED, or already EXPIRED on a slow machine.
  const v1::Session ended = WaitForEnd(*c, finished->name());
  ASSERT_TRUE(ended.state() == v1::Session::FINISHED || ended.state() == v1::Session::EXPIRED)
      << v1::Session::State_Name(ended.state());
  v1::Session now;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  do {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    auto got = c->GetSession(finished->name());
    ASSERT_TRUE(got.ok());
    now = *got;
  } while (now.state() != v1::Session::EXPIRED && std::chrono::steady_clock::now() < deadline);
  ASSERT_EQ(now.state(), v1::Session::EXPIRED);
  EXPECT_NE(now.state_message().find("retention"), std::string::npos) << now.state_message();
  auto traj = c->GetTrajectory(finished->name());
  EXPECT_EQ(traj.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(traj.status().message().find("EXPIRED"), std::string::npos);
  std::vector<v1::SessionEvent> events;
  Status end = c->Watch(finished->name(), 0, [&](const v1::SessionEvent& e) {
    events.push_back(e);
    return true;
  });
  ASSERT_TRUE(end.ok()) << end.ToString();
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].state_change().state(), v1::Session::EXPIRED);
  EXPECT_EQ(events[0].sequence(), now.last_sequence());
  EXPECT_GT(events[0].sequence(), 10u);  // after the session's own events
  auto other = c->GetSession(waiting->name());
  ASSERT_TRUE(other.ok());
  EXPECT_EQ(other->state(), v1::Session::CREATED);
}

// Uploads the test drive to a new session of `c` and waits for its end.
v1::Session RunUpload(SlapseClient& c, const v1::Session& request, const std::string& bytes) {
  auto created = c.CreateSession(request);
  EXPECT_TRUE(created.ok()) << created.status().ToString();
  if (!created.ok()) return {};
  EXPECT_TRUE(c.UploadBytes(created->name(), bytes).ok());
  return WaitForEnd(c, created->name());
}

// --retention-max-store-mb: with room for two and a half sessions' results,
// the store going over its budget expires the finished sessions whose end is
// oldest (EXPIRED, saying why), keeps the newest and never touches an active
// one; the store is back under the budget.
TEST_F(ServerTest, RetentionBudgetExpiresTheOldestFinishedSessions) {
  // One session's bytes in the store, measured on a server without a budget.
  int64_t empty_bytes = 0, session_bytes = 0;
  {
    auto calibration = StartServerWithRetention(0);
    ASSERT_TRUE(calibration.ok()) << calibration.status().ToString();
    auto c = SlapseClient::Connect("127.0.0.1:" + std::to_string((*calibration)->port()),
                                   TestClientOptions());
    empty_bytes = (*calibration)->sessions().StoreBytes();
    ASSERT_EQ(RunUpload(*c, UploadRequest(), *drive_).state(), v1::Session::FINISHED);
    session_bytes = (*calibration)->sessions().StoreBytes() - empty_bytes;
    (*calibration)->Shutdown();
  }
  ASSERT_GT(empty_bytes, 0);
  ASSERT_GT(session_bytes, 4 * 4096) << "a session's results span several pages";
  const int64_t budget = empty_bytes + session_bytes * 5 / 2;
  auto server = StartServerWithRetention(0, budget);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  auto c =
      SlapseClient::Connect("127.0.0.1:" + std::to_string((*server)->port()), TestClientOptions());
  auto waiting = c->CreateSession(UploadRequest());  // CREATED: active, never expires
  ASSERT_TRUE(waiting.ok());
  std::vector<std::string> names;
  for (int i = 0; i < 4; ++i) {
    const v1::Session ended = RunUpload(*c, UploadRequest(), *drive_);
    ASSERT_TRUE(ended.state() == v1::Session::FINISHED || ended.state() == v1::Session::EXPIRED)
        << v1::Session::State_Name(ended.state());
    names.push_back(ended.name());
  }
  // The retention pass runs every second: at least the two oldest go (a third
  // only if the expired sessions' rows and part-used pages weigh half a
  // session), oldest first, never the newest.
  std::vector<v1::Session> now(4);
  auto read_all = [&] {
    for (int i = 0; i < 4; ++i) {
      auto got = c->GetSession(names[i]);
      ASSERT_TRUE(got.ok()) << got.status().ToString();
      now[i] = *got;
    }
  };
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  do {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    read_all();
  } while ((now[0].state() != v1::Session::EXPIRED || now[1].state() != v1::Session::EXPIRED) &&
           std::chrono::steady_clock::now() < deadline);
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // later passes: settled
  read_all();
  int expired = 0;
  while (expired < 4 && now[expired].state() == v1::Session::EXPIRED) ++expired;
  ASSERT_GE(expired, 2);
  ASSERT_LE(expired, 3);
  for (int i = 0; i < expired; ++i) {
    EXPECT_NE(now[i].state_message().find("over its"), std::string::npos) << now[i].state_message();
    EXPECT_NE(now[i].state_message().find("budget"), std::string::npos) << now[i].state_message();
    EXPECT_NE(now[i].state_message().find("--retention-max-store-mb"), std::string::npos);
    auto traj = c->GetTrajectory(names[i]);
    EXPECT_EQ(traj.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_NE(traj.status().message().find("EXPIRED"), std::string::npos)
        << traj.status().message();
  }
  for (int i = expired; i < 4; ++i) {
    EXPECT_EQ(now[i].state(), v1::Session::FINISHED) << i << ": " << now[i].state_message();
    auto traj = c->GetTrajectory(names[i]);
    ASSERT_TRUE(traj.ok()) << traj.status().ToString();
    EXPECT_GT(traj->points_size(), 0);
  }
  std::vector<v1::SessionEvent> events;
  Status end = c->Watch(names[0], 0, [&](const v1::SessionEvent& e) {
    events.push_back(e);
    return true;
  });
  ASSERT_TRUE(end.ok()) << end.ToString();
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].state_change().state(), v1::Session::EXPIRED);
  EXPECT_EQ(events[0].state_change().message(), now[0].state_message());
  auto other = c->GetSession(waiting->name());
  ASSERT_TRUE(other.ok());
  EXPECT_EQ(other->state(), v1::Session::CREATED);
  EXPECT_LE((*server)->sessions().StoreBytes(), budget);
}

// Over the budget with nothing finished to expire (here the schema alone is
// over a 1-byte budget): the active session is untouched and the log says
// so once, not at every pass.
TEST_F(ServerTest, RetentionBudgetNeverTouchesActiveSessionsAndSaysSoOnce) {
  ::testing::internal::CaptureStderr();
  auto server = StartServerWithRetention(0, 1);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  auto c =
      SlapseClient::Connect("127.0.0.1:" + std::to_string((*server)->port()), TestClientOptions());
  auto waiting = c->CreateSession(UploadRequest());
  ASSERT_TRUE(waiting.ok()) << waiting.status().ToString();
  std::this_thread::sleep_for(std::chrono::milliseconds(3500));  // three passes or more
  auto got = c->GetSession(waiting->name());
  (*server)->Shutdown();
  const std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::CREATED);
  const std::string said = "no finished session left to expire";
  const size_t first = log.find(said);
  ASSERT_NE(first, std::string::npos) << log;
  EXPECT_EQ(log.find(said, first + 1), std::string::npos) << "said once:\n" << log;
}

// grpc.health.v1.Health/Check without generated stubs: an empty request (all
// services) answers HealthCheckResponse{status: SERVING} = bytes 08 01.
TEST_F(ServerTest, HealthCheckAnswersServing) {
  auto channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(server_->port()),
                                     grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  grpc::CompletionQueue cq;
  grpc::ByteBuffer request, response;
  grpc::Slice empty("");
  request = grpc::ByteBuffer(&empty, 1);
  auto call = stub.PrepareUnaryCall(&context, "/grpc.health.v1.Health/Check", request, &cq);
  call->StartCall();
  grpc::Status status;
  call->Finish(&response, &status, reinterpret_cast<void*>(1));
  void* tag = nullptr;
  bool ok = false;
  ASSERT_TRUE(cq.Next(&tag, &ok));
  ASSERT_TRUE(status.ok()) << status.error_message();
  std::vector<grpc::Slice> slices;
  ASSERT_TRUE(response.Dump(&slices).ok());
  std::string bytes;
  for (const grpc::Slice& sl : slices)
    bytes.append(reinterpret_cast<const char*>(sl.begin()), sl.size());
  EXPECT_EQ(bytes, std::string("\x08\x01", 2));
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
}

TEST_F(ServerTest, ShutdownEndsWatchersWithStopped) {
  auto small = StartServer(1);
  ASSERT_TRUE(small.ok()) << small.status().ToString();
  auto c =
      SlapseClient::Connect("127.0.0.1:" + std::to_string((*small)->port()), TestClientOptions());
  auto created = c->CreateSession(UploadRequest());
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  std::vector<v1::SessionEvent> events;
  Status end;
  std::thread watcher([&] {
    end = c->Watch(created->name(), 0, [&](const v1::SessionEvent& e) {
      events.push_back(e);
      return true;
    });
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  (*small)->Shutdown();
  watcher.join();
  EXPECT_TRUE(end.ok()) << end.ToString();
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state_change().state(), v1::Session::STOPPED);
}

TEST(UploadQueueTest, BlocksTheWriterWhenFullAndLimitsTheTotal) {
  server::UploadQueueOptions o;
  o.capacity_bytes = 10;
  o.max_total_bytes = 30;
  server::UploadQueue q(o);
  ASSERT_TRUE(q.Write("12345678", nullptr).ok());
  std::atomic<bool> second_done{false};
  std::thread writer([&] {
    EXPECT_TRUE(q.Write("abcdefgh", nullptr).ok());
    second_done = true;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  EXPECT_FALSE(second_done) << "a full buffer holds the writer";
  uint8_t buf[64];
  EXPECT_EQ(q.Read(buf, 64), 8);
  writer.join();
  EXPECT_TRUE(second_done);
  EXPECT_EQ(q.Read(buf, 64), 8);
  Status over = q.Write(std::string(20, 'x'), nullptr);
  EXPECT_EQ(over.code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(q.Read(buf, 64), -1) << "the reader fails too";
}

}  // namespace
}  // namespace slapse
