// RTSP push ingest on the server's one RTSP port (server/rtsp_ingest.h,
// gst-rtsp-server): real publishers (ffmpeg, and GStreamer's rtspclientsink
// through tests/rtsp_publish.py; ANNOUNCE / RECORD over TCP) and raw RTSP
// requests against a real server on loopback.
//   - two sessions publish on the same port at once, each to its own path,
//     and each equals the offline run of its own drive;
//   - no or wrong credentials: 401 (another session's: refused too), the
//     session untouched;
//   - an unknown path: 404; a second publisher to a busy path: refused;
//   - TEARDOWN ends FINISHED, a killed publisher FAILED (UNAVAILABLE, "lost");
//   - a publisher recording over UDP gets its server ports from --rtp-ports;
//   - the ingest sends a TCP publisher nothing it did not ask for (no RTCP),
//     so ffmpeg's TEARDOWN-and-close is never turned into an abort.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <dirent.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "api/convert.h"
#include "client/lib/client.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "core/pipeline/result_io.h"
#include "server/rtsp_ingest.h"
#include "server/server.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::SlapseClient;
using server::SlapseServer;
using testing::FfmpegProcess;
using testing::PublishUrl;
using testing::RtspRequestStatus;

// A minimal valid ANNOUNCE body (MPEG-2 video, static payload type 32).
constexpr const char* kSdp =
    "v=0\r\no=- 0 0 IN IP4 127.0.0.1\r\ns=test\r\nc=IN IP4 127.0.0.1\r\nt=0 0\r\n"
    "m=video 0 RTP/AVP 32\r\na=rtpmap:32 MPV/90000\r\na=control:streamid=0\r\n";

// The fixture servers' RTP port range (serve --rtp-ports). Another program
// holding a pair in it only makes the ingest skip that pair.
constexpr server::UdpPortRange kRtpPorts{47000, 47099};

// The local UDP ports of the sockets this process holds (the in-process
// server's): the inodes of /proc/self/fd's sockets, looked up in
// /proc/self/net/udp and udp6 (columns: sl local_address:port(hex) ... inode).
std::set<int> OwnUdpPorts() {
  std::set<std::string> inodes;
  if (DIR* dir = opendir("/proc/self/fd")) {
    while (dirent* e = readdir(dir)) {
      char target[256];
      const std::string path = std::string("/proc/self/fd/") + e->d_name;
      const ssize_t n = readlink(path.c_str(), target, sizeof(target) - 1);
      if (n <= 0) continue;
      const std::string link(target, static_cast<size_t>(n));
      if (link.rfind("socket:[", 0) == 0) inodes.insert(link.substr(8, link.size() - 9));
    }
    closedir(dir);
  }
  std::set<int> ports;
  for (const char* table : {"/proc/self/net/udp", "/proc/self/net/udp6"}) {
    std::ifstream in(table);
    std::string line;
    std::getline(in, line);  // the header
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      std::string sl, local, remote, st, queues, tr, retrnsmt, uid, timeout, inode;
      fields >> sl >> local >> remote >> st >> queues >> tr >> retrnsmt >> uid >> timeout >> inode;
      if (inodes.count(inode) == 0) continue;
      ports.insert(std::stoi(local.substr(local.rfind(':') + 1), nullptr, 16));
    }
  }
  return ports;
}

// A TCP relay on loopback between one publisher and the RTSP ingest: copies
// both ways, and keeps what the ingest sent the publisher. Closes its side
// toward the ingest the way the publisher closed (FIN after all its bytes).
class TcpRelay {
 public:
  explicit TcpRelay(int target_port) : target_port_(target_port) {
    listen_fd_ = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof(sa);
    if (bind(listen_fd_, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) == 0 &&
        listen(listen_fd_, 1) == 0 &&
        getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&sa), &len) == 0) {
      port_ = ntohs(sa.sin_port);
    }
    thread_ = std::thread([this] { Run(); });
  }
  ~TcpRelay() {
    shutdown(listen_fd_, SHUT_RDWR);
    thread_.join();
    close(listen_fd_);
  }
  int port() const { return port_; }
  // Waits for the publisher's connection to end; what the ingest sent it.
  std::string ToPublisher() {
    thread_.join();
    thread_ = std::thread([] {});
    return to_publisher_;
  }

 private:
  static int Connect(int port) {
    const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_port = htons(static_cast<uint16_t>(port));
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) != 0) {
      close(fd);
      return -1;
    }
    return fd;
  }
  // Copies `from` to `to` until `from` ends; appends to `kept` if given.
  static void Copy(int from, int to, std::string* kept) {
    char buf[65536];
    ssize_t n;
    while ((n = recv(from, buf, sizeof(buf), 0)) > 0) {
      if (kept != nullptr) kept->append(buf, static_cast<size_t>(n));
      if (send(to, buf, static_cast<size_t>(n), MSG_NOSIGNAL) != n) break;
    }
  }
  void Run() {
    const int publisher = accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (publisher < 0) return;
    const int ingest = Connect(target_port_);
    if (ingest >= 0) {
      std::thread back([&] {
        Copy(ingest, publisher, &to_publisher_);
        shutdown(publisher, SHUT_WR);
      });
      Copy(publisher, ingest, nullptr);
      shutdown(ingest, SHUT_WR);  // the publisher's FIN, after all its bytes
      back.join();
      close(ingest);
    }
    close(publisher);
  }

  int target_port_;
  int listen_fd_ = -1;
  int port_ = 0;
  std::string to_publisher_;
  std::thread thread_;
};

// What `slapse run` computes from a file with a session's default options.
struct Offline {
  int64_t frames = 0;
  std::vector<TimedPose> trajectory;
};

StatusOr<Offline> RunOffline(const testing::TestDrive& drive) {
  auto reader = MvReader::Open(drive.video_path);
  if (!reader.ok()) return reader.status();
  Intrinsics k = drive.intrinsics;
  k.width_px = (*reader)->info().width_px;
  k.height_px = (*reader)->info().height_px;
  Pipeline pipeline(k, (*reader)->info().mv_sigma_px(), PipelineOptions{});
  Offline out;
  FrameRecord frame;
  Status end;
  while ((end = (*reader)->Next(&frame)).ok()) {
    auto step = pipeline.Push(frame);
    if (!step.ok()) return step.status();
    ++out.frames;
  }
  if (end.code() != StatusCode::kOutOfRange) return end;
  pipeline.Finish();  // as the server at the stream's end: the open chain is posed
  out.trajectory = TimedPosesOf(pipeline.poses());
  return out;
}

class RtspPushTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    for (uint64_t seed : {31, 32}) {
      auto drive =
          testing::SimulateTestDrive("rtsp_push_test", testing::SmallMpeg2DriveOptions(seed, 3.0));
      ASSERT_TRUE(drive.ok()) << drive.status().ToString();
      auto offline = RunOffline(*drive);
      ASSERT_TRUE(offline.ok()) << offline.status().ToString();
      drives_.push_back(std::move(*drive));
      offline_.push_back(std::move(*offline));
    }
  }

  // --gtest_repeat runs SetUpTestSuite again.
  static void TearDownTestSuite() {
    drives_.clear();
    offline_.clear();
  }

  void SetUp() override {
    ASSERT_EQ(drives_.size(), 2u);
    for (const Offline& o : offline_) ASSERT_GE(o.trajectory.size(), 5u);  // not vacuous
    server::ServerOptions o;
    o.address = "127.0.0.1";
    o.port = 0;
    o.sessions.max_sessions = 4;
    o.sessions.rtsp_port = 0;  // a free one: ctest runs tests side by side
    o.sessions.rtp_ports = kRtpPorts;
    o.shutdown_grace_s = 1;
    auto server = SlapseServer::Start(o);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    rtsp_port_ = server_->sessions().rtsp_port();
    ASSERT_GT(rtsp_port_, 0);
    client_ = SlapseClient::Connect("127.0.0.1:" + std::to_string(server_->port()),
                                    testing::TestClientOptions());
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  v1::Session Create(const std::string& path, int drive = 0) {
    v1::Session request;
    request.mutable_rtsp_push()->set_path(path);
    request.mutable_rtsp_push()->set_start_timeout_ms(20000);
    request.mutable_rtsp_push()->set_receive_timeout_ms(5000);
    *request.mutable_intrinsics() = api::IntrinsicsToProto(drives_[drive].intrinsics);
    auto created = client_->CreateSession(request);
    EXPECT_TRUE(created.ok()) << created.status().ToString();
    return created.ok() ? *created : v1::Session();
  }

  std::unique_ptr<FfmpegProcess> Publish(const std::string& url, int drive = 0,
                                         const std::string& transport = "tcp") {
    return std::make_unique<FfmpegProcess>(
        std::vector<std::string>{"-re", "-i", drives_[drive].video_path, "-c", "copy", "-f", "rtsp",
                                 "-rtsp_transport", transport, url});
  }

  // Watches `name` to its final event; returns the last StateChange.
  v1::StateChange WatchToEnd(const std::string& name) {
    v1::StateChange last;
    Status watched = client_->Watch(name, 0, [&](const v1::SessionEvent& e) {
      if (e.has_state_change()) last = e.state_change();
      return true;
    });
    EXPECT_TRUE(watched.ok()) << watched.ToString();
    return last;
  }

  // Polls until the session has decoded `frames` frames (10 s at most).
  int64_t WaitForFrames(const std::string& name, int64_t frames) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    int64_t got = 0;
    while (got < frames && std::chrono::steady_clock::now() < deadline) {
      auto s = client_->GetSession(name);
      if (!s.ok()) break;
      got = s->stats().frames();
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return got;
  }

  // `time_tol_s` / `pose_tol` (relative to max(1, |value|)): 1e-9 when the
  // publisher sends the file's own 90 kHz timestamps (ffmpeg -c copy);
  // looser for one that re-stamps them.
  void ExpectEqualsOffline(const std::string& name, const Offline& offline,
                           double time_tol_s = 1e-9, double pose_tol = 1e-9) {
    auto session = client_->GetSession(name);
    auto trajectory = client_->GetTrajectory(name);
    ASSERT_TRUE(session.ok()) << session.status().ToString();
    ASSERT_TRUE(trajectory.ok()) << trajectory.status().ToString();
    EXPECT_EQ(session->stats().frames(), offline.frames);
    ASSERT_EQ(trajectory->points_size(), static_cast<int>(offline.trajectory.size()));
    // The same coded frames with the same 90 kHz timestamps (RTP's, kept
    // exactly through MPEG-TS) give the same vectors, so the same poses.
    for (size_t i = 0; i < offline.trajectory.size(); ++i) {
      const TimedPose& o = offline.trajectory[i];
      const v1::Trajectory::Point& s = trajectory->points(static_cast<int>(i));
      SCOPED_TRACE("pose " + std::to_string(i));
      EXPECT_EQ(s.anchor_index(), o.index);
      EXPECT_NEAR(s.timestamp_s(), o.timestamp_s, time_tol_s);
      EXPECT_NEAR(s.world_from_cam().tx(), o.world_from_cam.translation.x(),
                  pose_tol * std::max(1.0, std::abs(o.world_from_cam.translation.x())));
      EXPECT_NEAR(s.world_from_cam().ty(), o.world_from_cam.translation.y(),
                  pose_tol * std::max(1.0, std::abs(o.world_from_cam.translation.y())));
      EXPECT_NEAR(s.world_from_cam().tz(), o.world_from_cam.translation.z(),
                  pose_tol * std::max(1.0, std::abs(o.world_from_cam.translation.z())));
      EXPECT_NEAR(s.world_from_cam().qx(), o.world_from_cam.rotation.x(),
                  pose_tol * std::max(1.0, std::abs(o.world_from_cam.rotation.x())));
      EXPECT_NEAR(s.world_from_cam().qy(), o.world_from_cam.rotation.y(),
                  pose_tol * std::max(1.0, std::abs(o.world_from_cam.rotation.y())));
      EXPECT_NEAR(s.world_from_cam().qz(), o.world_from_cam.rotation.z(),
                  pose_tol * std::max(1.0, std::abs(o.world_from_cam.rotation.z())));
      EXPECT_NEAR(s.world_from_cam().qw(), o.world_from_cam.rotation.w(),
                  pose_tol * std::max(1.0, std::abs(o.world_from_cam.rotation.w())));
    }
  }

  static std::vector<testing::TestDrive> drives_;
  static std::vector<Offline> offline_;
  std::unique_ptr<SlapseServer> server_;
  std::unique_ptr<SlapseClient> client_;
  int rtsp_port_ = 0;
};

std::vector<testing::TestDrive> RtspPushTest::drives_;
std::vector<Offline> RtspPushTest::offline_;

TEST_F(RtspPushTest, TwoPublishersOnOnePortEachEqualTheirOfflineRun) {
  const v1::Session a = Create("gate", 0);
  const v1::Session b = Create("gate", 1);  // the same path: each under its own session
  ASSERT_FALSE(a.name().empty());
  ASSERT_FALSE(b.name().empty());
  const std::string port = ":" + std::to_string(rtsp_port_) + "/";
  EXPECT_EQ(a.ingest_url(),
            "rtsp://127.0.0.1" + port + a.name() + "/gate");  // name = "sessions/<id>"
  EXPECT_EQ(b.ingest_url(), "rtsp://127.0.0.1" + port + b.name() + "/gate");
  // The credentials are per session and shown at creation only.
  EXPECT_FALSE(a.publish_credentials().password().empty());
  EXPECT_NE(a.publish_credentials().password(), b.publish_credentials().password());
  auto got = client_->GetSession(a.name());
  ASSERT_TRUE(got.ok());
  EXPECT_FALSE(got->has_publish_credentials());
  // Output only: credentials a client puts in its request are dropped.
  v1::Session planted;
  planted.mutable_rtsp_push()->set_path("planted");
  planted.mutable_publish_credentials()->set_password("planted-by-the-client");
  *planted.mutable_intrinsics() = api::IntrinsicsToProto(drives_[0].intrinsics);
  auto with_planted = client_->CreateSession(planted);
  ASSERT_TRUE(with_planted.ok()) << with_planted.status().ToString();
  EXPECT_NE(with_planted->publish_credentials().password(), "planted-by-the-client");
  EXPECT_FALSE(client_->GetSession(with_planted->name())->has_publish_credentials());
  ASSERT_TRUE(client_->DeleteSession(with_planted->name()).ok());
  auto listed = client_->ListSessions(v1::ListSessionsRequest());
  ASSERT_TRUE(listed.ok());
  for (const v1::Session& s : listed->sessions()) EXPECT_FALSE(s.has_publish_credentials());

  v1::StateChange end_a, end_b;
  std::thread watch_a([&] { end_a = WatchToEnd(a.name()); });
  std::thread watch_b([&] { end_b = WatchToEnd(b.name()); });
  auto cam_a = Publish(PublishUrl(a), 0);
  auto cam_b = Publish(PublishUrl(b), 1);
  EXPECT_EQ(cam_a->Wait(std::chrono::seconds(20)), 0);
  EXPECT_EQ(cam_b->Wait(std::chrono::seconds(20)), 0);
  watch_a.join();
  watch_b.join();
  EXPECT_EQ(end_a.state(), v1::Session::FINISHED) << end_a.message();
  EXPECT_EQ(end_b.state(), v1::Session::FINISHED) << end_b.message();
  EXPECT_NE(end_a.message().find("TEARDOWN"), std::string::npos) << end_a.message();
  {
    SCOPED_TRACE("session a (drive 0)");
    ExpectEqualsOffline(a.name(), offline_[0]);
  }
  {
    SCOPED_TRACE("session b (drive 1)");
    ExpectEqualsOffline(b.name(), offline_[1]);
  }
  // Ended: the path is unmounted.
  EXPECT_EQ(RtspRequestStatus(rtsp_port_, "ANNOUNCE", a.ingest_url(), kSdp), 404);
}

// GStreamer's rtspclientsink as the camera (Digest auth, RTP over TCP,
// TEARDOWN at the end): the same result as ffmpeg's.
// DISABLED, KNOWN BUG (issue 15), now narrowed to rtspclientsink 1.22 itself.
// Found and fixed: rtsp_publish.py went PLAYING -> NULL at once, and
// rtspclientsink's READY -> NULL cancels its queued TEARDOWN (the session
// ended "lost without a TEARDOWN ... after 89 frames"); and the session's end
// closed the publisher's connection before gst-rtsp-server had sent the
// TEARDOWN's 200 OK. Left (2 failures in 20 runs, with or without 3 `yes` loops):
// (a) rtspclientsink never posts EOS: its RTP appsink got EOS, its RTCP
//     appsink never did after rtpsession sent the BYE ("is_eos: sink
//     'appsink1' did not post EOS yet" for 60 s), so the script never sends
//     TEARDOWN; all RTP was sent, the last frame waits for the server's EOS
//     drain and the session times out (receive_timeout_ms) one frame short.
// (b) its PAUSE is answered before READY queues the CLOSE; its thread is
//     then back in its receive loop, which CLOSE (mask CMD_PAUSE) does not
//     interrupt ("not interrupting busy cmd LOOP"), so TEARDOWN waits for the
//     next message from the server (an RTCP RR, ~5 s): receive_timeout_ms
//     first. The ffmpeg publishers' tests (exact to 1e-9) cover the server's
//     path. Run it with --gtest_also_run_disabled_tests (--gtest_repeat works).
TEST_F(RtspPushTest, DISABLED_AGStreamerPublisherEqualsTheOfflineRunToo) {
  const v1::Session a = Create("gst", 1);
  ASSERT_FALSE(a.name().empty());
  const int rc = testing::RunCommand(std::string(SLAPSE_RTSP_PUBLISH_PY) + " " +
                                     drives_[1].video_path + " '" + PublishUrl(a) + "'");
  EXPECT_EQ(rc, 0);
  const v1::StateChange end = WatchToEnd(a.name());
  EXPECT_EQ(end.state(), v1::Session::FINISHED) << end.message();
  EXPECT_NE(end.message().find("TEARDOWN"), std::string::npos) << end.message();
  // rtspclientsink re-stamps: its RTP timestamps are the file's truncated to
  // ns and back, some a 90 kHz tick (11 us) early, so dt is off by up to
  // 11 us in 33 ms (3e-4) on those frames: the same frames and anchors, times
  // within a tick, poses within 1e-3 relative (1e-4 seen).
  ExpectEqualsOffline(a.name(), offline_[1], 1.2e-5, 1e-3);
}

TEST_F(RtspPushTest, WrongCredentialsAre401AndTheSessionIsUntouched) {
  const v1::Session a = Create("cam", 0);
  const v1::Session other = Create("cam", 0);
  ASSERT_FALSE(a.name().empty());
  // No credentials at all: 401, exactly.
  EXPECT_EQ(RtspRequestStatus(rtsp_port_, "ANNOUNCE", a.ingest_url(), kSdp), 401);
  // A wrong password, and another session's valid credentials: ffmpeg is refused.
  v1::Session wrong = a;
  wrong.mutable_publish_credentials()->set_password("0123456789abcdef0123456789abcdef");
  EXPECT_NE(Publish(PublishUrl(wrong))->Wait(std::chrono::seconds(10)), 0);
  v1::Session borrowed = a;
  *borrowed.mutable_publish_credentials() = other.publish_credentials();
  EXPECT_NE(Publish(PublishUrl(borrowed))->Wait(std::chrono::seconds(10)), 0);
  auto untouched = client_->GetSession(a.name());
  ASSERT_TRUE(untouched.ok());
  EXPECT_EQ(untouched->state(), v1::Session::CREATED);
  EXPECT_EQ(untouched->stats().frames(), 0);
  // The right credentials still work after the refusals.
  auto cam = Publish(PublishUrl(a));
  EXPECT_EQ(cam->Wait(std::chrono::seconds(20)), 0);
  const v1::StateChange end = WatchToEnd(a.name());
  EXPECT_EQ(end.state(), v1::Session::FINISHED) << end.message();
  EXPECT_EQ(client_->GetSession(a.name())->stats().frames(), offline_[0].frames);
}

TEST_F(RtspPushTest, UnknownPathIs404AndADeletedSessionsPathToo) {
  const std::string base = "rtsp://127.0.0.1:" + std::to_string(rtsp_port_);
  EXPECT_EQ(RtspRequestStatus(rtsp_port_, "ANNOUNCE", base + "/sessions/nosuchsession/cam", kSdp),
            404);
  EXPECT_EQ(RtspRequestStatus(rtsp_port_, "ANNOUNCE", base + "/cam", kSdp), 404);
  const v1::Session a = Create("cam", 0);
  ASSERT_FALSE(a.name().empty());
  EXPECT_EQ(RtspRequestStatus(rtsp_port_, "ANNOUNCE", a.ingest_url(), kSdp), 401);
  ASSERT_TRUE(client_->DeleteSession(a.name()).ok());
  // Unmounted by the session's end (the worker unwinds within moments).
  int status = 0;
  for (int i = 0; i < 100 && status != 404; ++i) {
    status = RtspRequestStatus(rtsp_port_, "ANNOUNCE", a.ingest_url(), kSdp);
    if (status != 404) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_EQ(status, 404);
}

TEST_F(RtspPushTest, ASecondPublisherIsRefusedAndTheFirstGoesOn) {
  const v1::Session a = Create("cam", 0);
  ASSERT_FALSE(a.name().empty());
  auto first = Publish(PublishUrl(a), 0);
  ASSERT_GE(WaitForFrames(a.name(), 10), 10);
  auto second = Publish(PublishUrl(a), 1);
  EXPECT_NE(second->Wait(std::chrono::seconds(10)), 0);
  EXPECT_EQ(first->Wait(std::chrono::seconds(20)), 0);
  const v1::StateChange end = WatchToEnd(a.name());
  EXPECT_EQ(end.state(), v1::Session::FINISHED) << end.message();
  ExpectEqualsOffline(a.name(), offline_[0]);  // the second publisher's frames never mixed in
}

TEST_F(RtspPushTest, AKilledPublisherIsALostCameraNotAnEnd) {
  const v1::Session a = Create("cam", 0);
  ASSERT_FALSE(a.name().empty());
  auto cam = Publish(PublishUrl(a), 0);
  ASSERT_GE(WaitForFrames(a.name(), 10), 10);
  cam->Kill();  // SIGKILL: the TCP connection closes without TEARDOWN
  const v1::StateChange end = WatchToEnd(a.name());
  EXPECT_EQ(end.state(), v1::Session::FAILED) << end.message();
  auto got = client_->GetSession(a.name());
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kUnavailable));
  EXPECT_NE(got->error().message().find("lost without a TEARDOWN"), std::string::npos)
      << got->error().message();
}

// The publisher's TEARDOWN must reach the ingest. ffmpeg sends it without
// waiting for the answer and closes its socket at once; a TCP socket closed
// with unread bytes in it is aborted (RST), and what was still queued to
// send (the TEARDOWN, held back by Nagle behind the RTCP BYE) is thrown
// away. The ingest sent receiver reports (RTCP RR, every few seconds) over
// the publisher's connection, which ffmpeg reads only between packets: one
// that arrived in the last moment cost the TEARDOWN, and the session FAILED
// "lost without a TEARDOWN" after all but the last frame (2 of ~670 in the
// soak, docs/BENCHMARKS.md). So the ingest sends a publisher nothing but the
// answers to its requests: over 6 s of publishing (receiver reports came
// every 2.5 to 5 s), not one interleaved ('$') byte.
TEST_F(RtspPushTest, TheIngestSendsAPublisherNothingButAnswers) {
  const v1::Session a = Create("relayed", 0);
  ASSERT_FALSE(a.name().empty());
  TcpRelay relay(rtsp_port_);
  ASSERT_GT(relay.port(), 0);
  std::string url = PublishUrl(a);
  const std::string ingest_port = ":" + std::to_string(rtsp_port_) + "/";
  url.replace(url.find(ingest_port), ingest_port.size(), ":" + std::to_string(relay.port()) + "/");
  FfmpegProcess cam({"-re", "-stream_loop", "1", "-i", drives_[0].video_path, "-c", "copy", "-f",
                     "rtsp", "-rtsp_transport", "tcp", url});
  EXPECT_EQ(cam.Wait(std::chrono::seconds(30)), 0);
  const std::string to_publisher = relay.ToPublisher();
  EXPECT_NE(to_publisher.find("RTSP/1.0 200 OK"), std::string::npos);  // RECORD was answered
  EXPECT_EQ(to_publisher.find('$'), std::string::npos)
      << "the ingest sent the publisher interleaved data (RTCP): "
      << to_publisher.size() - std::min(to_publisher.size(), to_publisher.find('$')) << " bytes";
  const v1::StateChange end = WatchToEnd(a.name());
  EXPECT_EQ(end.state(), v1::Session::FINISHED) << end.message();
  EXPECT_NE(end.message().find("TEARDOWN"), std::string::npos) << end.message();
  // The loop's seam may cost a frame (ffmpeg -stream_loop -c copy).
  EXPECT_GT(client_->GetSession(a.name())->stats().frames(), offline_[0].frames);
}

// RECORD over UDP: the server's RTP/RTCP ports come from the configured
// range (what a container publishes), and the stream gets through.
TEST_F(RtspPushTest, AUdpPublisherGetsItsServerPortsFromTheRtpRange) {
  const auto in_range = [](const std::set<int>& ports) {
    std::vector<int> out;
    for (int p : ports) {
      if (p >= kRtpPorts.min_port && p <= kRtpPorts.max_port) out.push_back(p);
    }
    return out;
  };
  ASSERT_TRUE(in_range(OwnUdpPorts()).empty());  // before any publisher
  const v1::Session a = Create("udp", 0);
  ASSERT_FALSE(a.name().empty());
  auto cam = Publish(PublishUrl(a), 0, "udp");
  ASSERT_GE(WaitForFrames(a.name(), 10), 10) << "no frames over UDP";
  // RTP/RTCP pairs from the range (gst-rtsp-server binds one pair per
  // address family it serves: IPv4, and IPv6 where the host has it).
  const std::vector<int> ports = in_range(OwnUdpPorts());
  ASSERT_GE(ports.size(), 2u) << "no RTP/RTCP pair from " << kRtpPorts.ToString();
  ASSERT_EQ(ports.size() % 2, 0u);
  for (size_t i = 0; i < ports.size(); i += 2) {
    EXPECT_EQ(ports[i] % 2, 0) << ports[i];
    EXPECT_EQ(ports[i + 1], ports[i] + 1) << ports[i];
  }
  EXPECT_EQ(cam->Wait(std::chrono::seconds(20)), 0);
  const v1::StateChange end = WatchToEnd(a.name());
  EXPECT_EQ(end.state(), v1::Session::FINISHED) << end.message();
}

TEST_F(RtspPushTest, NoPublisherIsDeadlineExceeded) {
  v1::Session request;
  request.mutable_rtsp_push()->set_path("nobody");
  request.mutable_rtsp_push()->set_start_timeout_ms(300);
  *request.mutable_intrinsics() = api::IntrinsicsToProto(drives_[0].intrinsics);
  auto created = client_->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const v1::StateChange end = WatchToEnd(created->name());
  EXPECT_EQ(end.state(), v1::Session::FAILED);
  EXPECT_EQ(client_->GetSession(created->name())->error().code(),
            static_cast<int>(StatusCode::kDeadlineExceeded));
}

// The RTSP port taken: the server does not start, and says which flag moves it.
TEST_F(RtspPushTest, ATakenRtspPortIsUnavailable) {
  server::ServerOptions o;
  o.port = 0;
  o.sessions.rtsp_port = rtsp_port_;  // this fixture's server has it
  auto second = SlapseServer::Start(o);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(second.status().message().find("--rtsp-port"), std::string::npos)
      << second.status().message();
}

// --rtsp-url-host: ingest URLs name the cameras' way to the port (here a
// stable DNS name) while the port binds --rtsp-host; a name that cannot be
// a URL host is refused at start.
TEST_F(RtspPushTest, IngestUrlsNameTheUrlHostAndABadOneIsRefused) {
  server::ServerOptions o;
  o.port = 0;
  o.sessions.rtsp_url_host = "slapse-0.slapse-pods";
  auto named = SlapseServer::Start(o);
  ASSERT_TRUE(named.ok()) << named.status().ToString();
  auto client = SlapseClient::Connect("127.0.0.1:" + std::to_string((*named)->port()),
                                      testing::TestClientOptions());
  v1::Session request;
  request.mutable_rtsp_push()->set_path("cam1");
  *request.mutable_intrinsics() = api::IntrinsicsToProto(drives_[0].intrinsics);
  auto created = client->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string expected =
      "rtsp://slapse-0.slapse-pods:" + std::to_string((*named)->sessions().rtsp_port()) +
      "/sessions/";
  EXPECT_EQ(created->ingest_url().rfind(expected, 0), 0u) << created->ingest_url();
  (*named)->Shutdown();
  for (const char* bad : {"user@host", "host/path", "-host", "a b"}) {
    o.sessions.rtsp_url_host = bad;
    auto refused = SlapseServer::Start(o);
    ASSERT_FALSE(refused.ok()) << bad;
    EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(refused.status().message().find("--rtsp-url-host"), std::string::npos)
        << refused.status().message();
  }
}

// The credentials derive from the data directory's key: the same after a
// restart, different for another key.
TEST(RtspIngestKeyTest, TheKeyFilePersistsAndInMemoryKeysDiffer) {
  const std::string dir = testing::MakeTempDir("rtsp_ingest_key");
  auto k1 = server::LoadOrCreateRtspIngestKey(dir);
  auto k2 = server::LoadOrCreateRtspIngestKey(dir);
  ASSERT_TRUE(k1.ok()) << k1.status().ToString();
  ASSERT_TRUE(k2.ok());
  EXPECT_EQ(*k1, *k2);
  EXPECT_EQ(k1->size(), 32u);
  auto m1 = server::LoadOrCreateRtspIngestKey(server::kInMemoryDataDir);
  auto m2 = server::LoadOrCreateRtspIngestKey(server::kInMemoryDataDir);
  ASSERT_TRUE(m1.ok() && m2.ok());
  EXPECT_NE(*m1, *m2);
}

}  // namespace
}  // namespace slapse
