// RTSP pull end to end: a real slapse server on 127.0.0.1 in-process, the
// real client library, and a real RTSP server as the camera: GStreamer's
// gst-rtsp-server (tests/rtsp_server.py) serving a simulated drive.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "api/validate.h"
#include "client/lib/client.h"
#include "core/mv/mv_reader.h"
#include "core/pipeline/pipeline.h"
#include "lab/sim/simulate.h"
#include "server/server.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::ClientOptions;
using client::SlapseClient;
using server::ServerOptions;
using server::SlapseServer;
using Clock = std::chrono::steady_clock;

// tests/rtsp_server.py serving `file` on 127.0.0.1:`port` (0: a free one).
// The constructor waits for its "READY <url>" line; the destructor kills
// (SIGKILL) and reaps it (testing::ChildProcess).
class RtspServerProcess : public testing::ChildProcess {
 public:
  RtspServerProcess(const std::string& file, int port) {
    int out[2];
    if (pipe(out) != 0) return;
    std::vector<std::string> argv = {SLAPSE_RTSP_SERVER_PY, file,     "--port",
                                     std::to_string(port),  "--path", "drive"};
    std::vector<char*> c;
    for (std::string& a : argv) c.push_back(a.data());
    c.push_back(nullptr);
    pid_ = fork();
    if (pid_ == 0) {
      dup2(out[1], 1);
      close_range(3, ~0U, 0);  // not the test's sockets (gRPC, other servers' pipes)
      execv(c[0], c.data());
      _exit(127);
    }
    close(out[1]);
    // Read the READY line (bounded: python and GStreamer start in < 1 s).
    std::string line;
    const auto deadline = Clock::now() + std::chrono::seconds(10);
    while (pid_ > 0 && line.find('\n') == std::string::npos && Clock::now() < deadline) {
      pollfd p{out[0], POLLIN, 0};
      if (poll(&p, 1, 100) <= 0) continue;
      char buf[256];
      const ssize_t n = read(out[0], buf, sizeof(buf));
      if (n <= 0) break;
      line.append(buf, static_cast<size_t>(n));
    }
    close(out[0]);
    const std::string ready = "READY ";
    if (line.rfind(ready, 0) == 0 && line.find('\n') != std::string::npos) {
      url_ = line.substr(ready.size(), line.find('\n') - ready.size());
      port_ = std::atoi(url_.c_str() + url_.rfind(':') + 1);
    }
  }
  // "rtsp://127.0.0.1:PORT/drive", empty if the server did not come up.
  const std::string& url() const { return url_; }
  int port() const { return port_; }

 private:
  std::string url_;
  int port_ = 0;
};

class RtspPullTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::string(testing::MakeTempDir("rtsp_pull_test"));
    auto drive =
        testing::SimulateTestDrive("rtsp_pull_test_drive", testing::SmallMpeg2DriveOptions(5, 3.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    drive_path_ = new std::string(drive->video_path);
    intrinsics_ = new Intrinsics(drive->intrinsics);
  }
  static void TearDownTestSuite() {
    delete dir_;
    delete drive_path_;
    delete intrinsics_;
  }

  void SetUp() override {
    ASSERT_NE(drive_path_, nullptr);
    server_ = StartServer(2);
    ASSERT_NE(server_, nullptr);
    client_ = Connect(*server_);
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  static std::unique_ptr<SlapseServer> StartServer(int max_sessions) {
    ServerOptions o;
    o.address = "127.0.0.1";
    o.port = 0;
    o.sessions.max_sessions = max_sessions;
    o.shutdown_grace_s = 1;
    auto server = SlapseServer::Start(o);
    EXPECT_TRUE(server.ok()) << server.status().ToString();
    return server.ok() ? std::move(*server) : nullptr;
  }
  // Every rpc has a deadline: a hang fails the test, it does not block ctest.
  static std::unique_ptr<SlapseClient> Connect(const SlapseServer& server) {
    ClientOptions o;
    o.rpc_timeout_s = 5;
    o.upload_timeout_s = 20;
    o.watch_timeout_s = 25;
    return SlapseClient::Connect("127.0.0.1:" + std::to_string(server.port()), o);
  }

  static v1::Session PullRequest(const std::string& url) {
    v1::Session s;
    s.mutable_rtsp_pull()->set_url(url);
    s.mutable_rtsp_pull()->set_start_timeout_ms(5000);
    s.mutable_rtsp_pull()->set_receive_timeout_ms(2000);
    v1::Intrinsics* k = s.mutable_intrinsics();
    k->set_fx_px(intrinsics_->fx_px);
    k->set_fy_px(intrinsics_->fy_px);
    k->set_cx_px(intrinsics_->cx_px);
    k->set_cy_px(intrinsics_->cy_px);
    return s;
  }
  static void SetPolicy(v1::Session* s, int attempts, int initial_ms, double factor, int max_ms) {
    v1::ReconnectPolicy* p = s->mutable_rtsp_pull()->mutable_reconnect();
    p->set_max_attempts(attempts);
    p->set_initial_interval_ms(initial_ms);
    p->set_backoff_multiplier(factor);
    p->set_max_interval_ms(max_ms);
  }

  std::vector<v1::SessionEvent> WatchAll(const std::string& name, Status* end) {
    std::vector<v1::SessionEvent> events;
    *end = client_->Watch(name, 0, [&](const v1::SessionEvent& e) {
      events.push_back(e);
      return true;
    });
    return events;
  }

  // Polls the session until `done` holds (true) or `timeout` passes (false).
  bool WaitFor(const std::string& name, std::chrono::milliseconds timeout,
               const std::function<bool(const v1::Session&)>& done, v1::Session* last = nullptr) {
    const auto deadline = Clock::now() + timeout;
    while (Clock::now() < deadline) {
      auto got = client_->GetSession(name);
      if (!got.ok()) return false;
      if (last != nullptr) *last = *got;
      if (done(*got)) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }

  static std::string* dir_;
  static std::string* drive_path_;
  static Intrinsics* intrinsics_;
  std::unique_ptr<SlapseServer> server_;
  std::unique_ptr<SlapseClient> client_;
};

std::string* RtspPullTest::dir_ = nullptr;
std::string* RtspPullTest::drive_path_ = nullptr;
Intrinsics* RtspPullTest::intrinsics_ = nullptr;

int CountPoses(const std::vector<v1::SessionEvent>& events) {
  int poses = 0;
  for (const auto& e : events) poses += e.has_pose();
  return poses;
}

// Without reconnects, the end of the served file finishes the session.
TEST_F(RtspPullTest, PullsASimulatedDriveToFinished) {
  RtspServerProcess camera(*drive_path_, 0);
  ASSERT_FALSE(camera.url().empty()) << "tests/rtsp_server.py did not start";
  auto created = client_->CreateSession(PullRequest(camera.url()));
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  EXPECT_TRUE(created->ingest_url().empty());
  Status end;
  std::vector<v1::SessionEvent> events = WatchAll(created->name(), &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  EXPECT_GT(CountPoses(events), 10);
  ASSERT_GE(events.size(), 3u);
  EXPECT_EQ(events.front().state_change().state(), v1::Session::CREATED);
  ASSERT_TRUE(events.back().has_state_change());
  EXPECT_EQ(events.back().state_change().state(), v1::Session::FINISHED)
      << events.back().state_change().message();
  EXPECT_NE(events.back().state_change().message().find("the stream ended"), std::string::npos)
      << events.back().state_change().message();
  auto got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FINISHED);
  EXPECT_GT(got->stats().frames(), 60) << "of the drive's 90";
  EXPECT_GT(got->stats().tracked_pairs(), 5);
  EXPECT_EQ(got->stats().reconnects(), 0);
  auto traj = client_->GetTrajectory(created->name());
  ASSERT_TRUE(traj.ok()) << traj.status().ToString();
  EXPECT_GT(traj->points_size(), 5);
}

// The camera ends its stream (the file's end: RTCP BYE, its RTSP connection
// still open): FINISHED at once, even with reconnects allowed.
TEST_F(RtspPullTest, CleanEndFinishesEvenWithReconnectsAllowed) {
  RtspServerProcess camera(*drive_path_, 0);
  ASSERT_FALSE(camera.url().empty()) << "tests/rtsp_server.py did not start";
  v1::Session request = PullRequest(camera.url());
  SetPolicy(&request, 3, 200, 2.0, 1000);
  auto created = client_->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  Status end;
  std::vector<v1::SessionEvent> events = WatchAll(created->name(), &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  for (const auto& e : events) EXPECT_FALSE(e.has_reconnecting()) << e.DebugString();
  auto got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FINISHED) << got->error().message();
  EXPECT_NE(got->state_message().find("the camera ended it"), std::string::npos)
      << got->state_message();
  EXPECT_EQ(got->stats().reconnects(), 0);
  EXPECT_GT(got->stats().frames(), 60) << "of the drive's 90";
}

// The camera process is killed mid-stream (kill -9: its TCP connection
// closes, which FFmpeg also reads as the end of input): without reconnects
// the session FAILS UNAVAILABLE "camera lost", not FINISHED.
TEST_F(RtspPullTest, KilledCameraWithoutReconnectFailsCameraLost) {
  RtspServerProcess camera(*drive_path_, 0);
  ASSERT_FALSE(camera.url().empty()) << "tests/rtsp_server.py did not start";
  auto created = client_->CreateSession(PullRequest(camera.url()));
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  v1::Session s;
  ASSERT_TRUE(WaitFor(
      created->name(), std::chrono::seconds(10),
      [](const v1::Session& x) { return x.stats().frames() >= 15; }, &s))
      << s.DebugString();
  camera.Kill();
  Status end;
  WatchAll(created->name(), &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  auto got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FAILED) << got->state_message();
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kUnavailable));
  const std::string& message = got->error().message();
  EXPECT_NE(message.find("camera lost"), std::string::npos) << message;
  EXPECT_NE(message.find("no longer answers"), std::string::npos) << message;
  EXPECT_NE(message.find("no reconnect"), std::string::npos) << message;
  EXPECT_LT(got->stats().frames(), 90) << "killed before the drive's end";
}

// Connection refused on every attempt: two retries after 200 and 400 ms, then
// FAILED with UNAVAILABLE naming the URL (without its password) and the error.
TEST_F(RtspPullTest, UnreachableCameraFailsUnavailableAfterTheBackoff) {
  const int port = testing::FreeLoopbackTcpPort();
  ASSERT_GT(port, 0);
  const std::string url = "rtsp://viewer:secret@127.0.0.1:" + std::to_string(port) + "/cam";
  v1::Session request = PullRequest(url);
  SetPolicy(&request, 2, 200, 2.0, 5000);
  const auto t0 = Clock::now();
  auto created = client_->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  Status end;
  std::vector<v1::SessionEvent> events = WatchAll(created->name(), &end);
  const auto elapsed = Clock::now() - t0;
  ASSERT_TRUE(end.ok()) << end.ToString();
  EXPECT_GE(elapsed, std::chrono::milliseconds(600)) << "the waits are 200 + 400 ms";
  EXPECT_LT(elapsed, std::chrono::seconds(10));

  std::vector<v1::Reconnecting> retries;
  for (const auto& e : events) {
    if (e.has_reconnecting()) retries.push_back(e.reconnecting());
  }
  ASSERT_EQ(retries.size(), 2u);
  EXPECT_EQ(retries[0].attempt(), 1);
  EXPECT_EQ(retries[0].delay_ms(), 200);
  EXPECT_EQ(retries[1].attempt(), 2);
  EXPECT_EQ(retries[1].delay_ms(), 400);
  EXPECT_EQ(retries[1].max_attempts(), 2);
  EXPECT_NE(retries[0].reason().find("Connection refused"), std::string::npos)
      << retries[0].reason();

  auto got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FAILED);
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kUnavailable));
  EXPECT_EQ(got->stats().reconnects(), 2);
  EXPECT_EQ(got->stats().frames(), 0);
  const std::string& message = got->error().message();
  EXPECT_NE(message.find("rtsp://***@127.0.0.1:" + std::to_string(port) + "/cam"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("Connection refused"), std::string::npos) << message;
  EXPECT_NE(message.find("2 reconnect attempt"), std::string::npos) << message;
  for (const auto& e : events) {
    EXPECT_EQ(e.DebugString().find("secret"), std::string::npos) << e.DebugString();
  }
}

// The RTSP server dies mid-stream and comes back on the same port: the
// session reconnects, keeps one trajectory with increasing anchor indices and
// stream times, and when the server dies for good it fails once the outage
// has used up its attempts.
TEST_F(RtspPullTest, ReconnectsWhenTheServerComesBackThenGivesUp) {
  auto camera = std::make_unique<RtspServerProcess>(*drive_path_, 0);
  ASSERT_FALSE(camera->url().empty()) << "tests/rtsp_server.py did not start";
  const int port = camera->port();
  v1::Session request = PullRequest(camera->url());
  SetPolicy(&request, 4, 300, 2.0, 1000);  // waits 300, 600, 1000, 1000 ms
  auto created = client_->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string name = created->name();
  Status watch_end;
  std::vector<v1::SessionEvent> events;
  std::thread watcher([&] { events = WatchAll(name, &watch_end); });

  v1::Session s;
  ASSERT_TRUE(WaitFor(
      name, std::chrono::seconds(10), [](const v1::Session& x) { return x.stats().frames() >= 20; },
      &s))
      << s.DebugString();
  camera->Kill();
  // The first retry is under way; bring the server back on the same port.
  EXPECT_TRUE(WaitFor(
      name, std::chrono::seconds(5),
      [](const v1::Session& x) { return x.stats().reconnects() >= 1; }, &s));
  const int64_t before = s.stats().frames();
  camera = std::make_unique<RtspServerProcess>(*drive_path_, port);
  ASSERT_FALSE(camera->url().empty()) << "could not restart the RTSP server on port " << port;
  EXPECT_TRUE(WaitFor(
      name, std::chrono::seconds(10),
      [&](const v1::Session& x) { return x.stats().frames() >= before + 30; }, &s))
      << s.DebugString();
  EXPECT_EQ(s.state(), v1::Session::RUNNING);
  const int reconnects = s.stats().reconnects();
  EXPECT_GE(reconnects, 1);

  // Gone for good: 4 more retries (300 + 600 + 1000 + 1000 ms), then FAILED.
  // The clock starts before the kill: the server may see the connection close
  // (and start its first 300 ms wait) while Kill() is still reaping the process.
  const auto t_kill = Clock::now();
  camera->Kill();
  watcher.join();  // bounded by the client's watch deadline
  const auto elapsed = Clock::now() - t_kill;
  ASSERT_TRUE(watch_end.ok()) << watch_end.ToString();
  EXPECT_GE(elapsed, std::chrono::milliseconds(2900));
  EXPECT_LT(elapsed, std::chrono::seconds(15));
  auto got = client_->GetSession(name);
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FAILED);
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kUnavailable))
      << got->error().message();
  EXPECT_NE(got->error().message().find("gave up after 4 reconnect attempt"), std::string::npos)
      << got->error().message();
  EXPECT_NE(got->error().message().find("camera lost after"), std::string::npos)
      << got->error().message();
  EXPECT_EQ(got->stats().reconnects(), reconnects + 4);
  EXPECT_GT(got->stats().frames(), before + 30);

  // Events: one RUNNING, poses on both sides of the first reconnect, anchor
  // indices and stream times increasing throughout.
  int running = 0, poses_after = 0;
  uint64_t first_retry = 0;
  int64_t last_anchor = -1;
  double last_time = -1;
  for (const auto& e : events) {
    if (e.has_state_change()) running += e.state_change().state() == v1::Session::RUNNING;
    if (e.has_reconnecting() && first_retry == 0) first_retry = e.sequence();
    if (!e.has_pose()) continue;
    poses_after += first_retry > 0;
    EXPECT_GT(e.pose().anchor_index(), last_anchor);
    EXPECT_GT(e.pose().timestamp_s(), last_time);
    last_anchor = e.pose().anchor_index();
    last_time = e.pose().timestamp_s();
  }
  EXPECT_EQ(running, 1);
  EXPECT_GT(first_retry, 0u);
  EXPECT_GT(poses_after, 3) << "the pipeline goes on after the reconnect";
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().state_change().state(), v1::Session::FAILED);
  auto traj = client_->GetTrajectory(name);
  ASSERT_TRUE(traj.ok()) << traj.status().ToString();
  for (int i = 1; i < traj->points_size(); ++i) {
    EXPECT_GT(traj->points(i).anchor_index(), traj->points(i - 1).anchor_index());
  }
}

// Without reconnects: a path the server does not serve fails at once with
// the server's answer; a server that falls silent fails the session after
// receive_timeout_ms. Both UNAVAILABLE, with what to look at in the message.
TEST_F(RtspPullTest, WrongPathAndSilentServerFailUnavailable) {
  RtspServerProcess camera(*drive_path_, 0);
  ASSERT_FALSE(camera.url().empty()) << "tests/rtsp_server.py did not start";
  auto wrong = client_->CreateSession(PullRequest(camera.url() + "-nope"));
  ASSERT_TRUE(wrong.ok()) << wrong.status().ToString();
  Status end;
  WatchAll(wrong->name(), &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  auto got = client_->GetSession(wrong->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FAILED);
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kUnavailable));
  EXPECT_NE(got->error().message().find("404"), std::string::npos) << got->error().message();
  EXPECT_NE(got->error().message().find(camera.url() + "-nope"), std::string::npos)
      << got->error().message();

  v1::Session request = PullRequest(camera.url());
  request.mutable_rtsp_pull()->set_receive_timeout_ms(1000);
  auto created = client_->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  v1::Session s;
  ASSERT_TRUE(WaitFor(
      created->name(), std::chrono::seconds(10),
      [](const v1::Session& x) { return x.stats().frames() >= 10; }, &s))
      << s.DebugString();
  camera.Freeze();
  const auto t0 = Clock::now();
  WatchAll(created->name(), &end);
  ASSERT_TRUE(end.ok()) << end.ToString();
  EXPECT_LT(Clock::now() - t0, std::chrono::seconds(5));
  got = client_->GetSession(created->name());
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  EXPECT_EQ(got->state(), v1::Session::FAILED);
  EXPECT_EQ(got->error().code(), static_cast<int>(StatusCode::kUnavailable));
  EXPECT_NE(got->error().message().find("receive_timeout_ms=1000"), std::string::npos)
      << got->error().message();
  EXPECT_GE(got->stats().frames(), 10);
}

// StopSession and DeleteSession end a reconnect wait at once: the worker is
// free for the next session long before the 20 s wait would end.
TEST_F(RtspPullTest, StopAndDeleteDuringABackoffWaitArePrompt) {
  auto one = StartServer(1);
  ASSERT_NE(one, nullptr);
  client_ = Connect(*one);
  const int port = testing::FreeLoopbackTcpPort();
  ASSERT_GT(port, 0);
  v1::Session request = PullRequest("rtsp://127.0.0.1:" + std::to_string(port) + "/cam");
  SetPolicy(&request, 5, 20000, 1.0, 20000);

  for (const bool use_delete : {false, true}) {
    auto created = client_->CreateSession(request);
    ASSERT_TRUE(created.ok()) << created.status().ToString();
    ASSERT_TRUE(WaitFor(created->name(), std::chrono::seconds(5),
                        [](const v1::Session& x) { return x.stats().reconnects() == 1; }));
    const auto t0 = Clock::now();
    if (use_delete) {
      ASSERT_TRUE(client_->DeleteSession(created->name()).ok());
    } else {
      auto stopped = client_->StopSession(created->name());
      ASSERT_TRUE(stopped.ok()) << stopped.status().ToString();
      EXPECT_EQ(stopped->state(), v1::Session::STOPPED);
    }
    // The single worker takes the next session at once: a pull of a closed
    // port without reconnect fails within milliseconds.
    v1::Session next = request;
    next.mutable_rtsp_pull()->clear_reconnect();
    auto probe = client_->CreateSession(next);
    ASSERT_TRUE(probe.ok()) << probe.status().ToString();
    v1::Session s;
    EXPECT_TRUE(WaitFor(
        probe->name(), std::chrono::seconds(5),
        [](const v1::Session& x) { return x.state() == v1::Session::FAILED; }, &s))
        << s.DebugString();
    EXPECT_LT(Clock::now() - t0, std::chrono::seconds(2)) << (use_delete ? "delete" : "stop");
    EXPECT_EQ(s.error().code(), static_cast<int>(StatusCode::kUnavailable));
    EXPECT_NE(s.error().message().find("no reconnect"), std::string::npos) << s.error().message();
  }

  // Shutdown ends a wait too.
  auto waiting = client_->CreateSession(request);
  ASSERT_TRUE(waiting.ok()) << waiting.status().ToString();
  ASSERT_TRUE(WaitFor(waiting->name(), std::chrono::seconds(5),
                      [](const v1::Session& x) { return x.stats().reconnects() == 1; }));
  const auto t0 = Clock::now();
  one->Shutdown();
  EXPECT_LT(Clock::now() - t0, std::chrono::seconds(3));
}

TEST_F(RtspPullTest, BadUrlOrPolicyIsInvalidArgument) {
  for (const std::string url :
       {"", "http://127.0.0.1/x", "127.0.0.1:554/x", "rtsp://", "rtsp:///x", "rtsp://:554/x",
        "rtsp://user@/x", "rtsp://cam:0/x", "rtsp://cam:65536/x", "rtsp://cam:/x",
        "rtsp://cam:x1/x", "rtsp://ca m/x", "rtsp://cam/x\n", "rtsp://[::1/x", "rtsp://c$m/x"}) {
    auto created = client_->CreateSession(PullRequest(url));
    EXPECT_EQ(created.status().code(), StatusCode::kInvalidArgument) << url;
    if (!url.empty()) {
      EXPECT_NE(created.status().message().find("rtsp_pull.url"), std::string::npos)
          << created.status().message();
    }
  }
  auto bad_policy = [&](int attempts, int initial_ms, double factor, int max_ms) {
    v1::Session request = PullRequest("rtsp://127.0.0.1:1/x");
    SetPolicy(&request, attempts, initial_ms, factor, max_ms);
    auto created = client_->CreateSession(request);
    EXPECT_NE(created.status().message().find("rtsp_pull.reconnect."), std::string::npos)
        << created.status().message();
    return created.status().code();
  };
  EXPECT_EQ(bad_policy(-1, 100, 2, 1000), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad_policy(2, -100, 2, 1000), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad_policy(2, 100, 0.5, 1000), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad_policy(2, 100, std::nan(""), 1000), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad_policy(2, 100, 2, -1), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad_policy(2, 1000, 2, 500), StatusCode::kInvalidArgument);
  v1::Session request = PullRequest("rtsp://127.0.0.1:1/x");
  request.mutable_rtsp_pull()->set_receive_timeout_ms(-1);
  EXPECT_EQ(client_->CreateSession(request).status().code(), StatusCode::kInvalidArgument);

  // Accepted forms (closed ports on 127.0.0.1: no DNS, they fail at once).
  for (const std::string url : {"rtsp://127.0.0.1:1/x", "RTSP://127.0.0.1:1",
                                "rtsps://u:p@127.0.0.1:1/a?b=c", "rtsp://[::1]:1/x"}) {
    auto created = client_->CreateSession(PullRequest(url));
    EXPECT_TRUE(created.ok()) << url << ": " << created.status().ToString();
    if (created.ok()) {
      // Responses carry the URL with its credentials masked (api::RedactUrl).
      EXPECT_EQ(created->rtsp_pull().url(), api::RedactUrl(url));
      Status end;
      WatchAll(created->name(), &end);  // let the session end: the server has 2 slots
      EXPECT_TRUE(end.ok()) << end.ToString();
    }
  }
}

// Pipeline::Break, which a reconnect uses: after it the trajectory goes on
// from the last pose, with increasing indices, and the filter tracks again.
TEST_F(RtspPullTest, PipelineBreakContinuesTheTrajectoryFromTheLastPose) {
  auto reader = MvReader::Open(*drive_path_);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  std::vector<FrameRecord> frames;
  FrameRecord f;
  while ((*reader)->Next(&f).ok()) frames.push_back(f);
  ASSERT_GE(frames.size(), 60u);
  Intrinsics k = *intrinsics_;
  k.width_px = (*reader)->info().width_px;
  k.height_px = (*reader)->info().height_px;
  Pipeline pipeline(k, (*reader)->info().mv_sigma_px());

  const size_t cut = frames.size() / 2;
  for (size_t i = 0; i < cut; ++i) ASSERT_TRUE(pipeline.Push(frames[i]).ok());
  const size_t n_before = pipeline.trajectory().size();
  ASSERT_GE(n_before, 3u);
  const auto last = pipeline.trajectory().back();

  pipeline.Break();
  // The "new connection" starts over at the drive's first frame.
  const int64_t offset = frames[cut - 1].index + 1;
  const double t_offset = frames[cut - 1].timestamp_s + 1.0;
  int tracking_after = 0;
  for (FrameRecord r : frames) {
    r.index += offset;
    if (r.prev_anchor_index >= 0) r.prev_anchor_index += offset;
    if (r.next_anchor_index >= 0) r.next_anchor_index += offset;
    r.timestamp_s += t_offset;
    auto step = pipeline.Push(r);
    ASSERT_TRUE(step.ok()) << step.status().ToString();
    if (step->has_value()) tracking_after += (*step)->tracking;
  }
  EXPECT_GT(tracking_after, 5);
  const auto& traj = pipeline.trajectory();
  ASSERT_GT(traj.size(), n_before + 5);
  // The re-initialised filter starts at the last pose before the break.
  EXPECT_GE(traj[n_before].index, offset);
  EXPECT_NEAR((traj[n_before].world_from_cam.translation - last.world_from_cam.translation).norm(),
              0.0, 1e-12);
  for (size_t i = 1; i < traj.size(); ++i) {
    EXPECT_GT(traj[i].index, traj[i - 1].index);
    EXPECT_GT(traj[i].timestamp_s, traj[i - 1].timestamp_s);
  }
}

}  // namespace
}  // namespace slapse
