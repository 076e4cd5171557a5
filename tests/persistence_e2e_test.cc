// Restart of the real `slapse serve` process on its data directory (SQLite):
// killed with SIGKILL mid-stream, then stopped cleanly (SIGTERM), each time
// restarted on the same directory. Nothing a client saw is lost (the
// durability rule of server/store.h), names are not reused, an RTSP push
// session waits for its camera again and resumes in a new segment, an
// interrupted upload ends FAILED with ABORTED, a finished session is as it was.
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "client/lib/client.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::SlapseClient;
using testing::FfmpegProcess;
using testing::PortOf;
using testing::TestClientOptions;
using testing::WaitForLocalPort;

// `slapse serve` on 127.0.0.1:port with `data_dir`; its output in `log`.
class ServeProcess : public testing::LoggedProcess {
 public:
  ServeProcess(int port, const std::string& data_dir, const std::string& log)
      : LoggedProcess({SLAPSE_CLI, "serve", "--address", "127.0.0.1", "--port",
                       std::to_string(port), "--data-dir", data_dir, "--max-sessions", "4",
                       // no HTTP and a free RTSP ingest port: 8080 and 8554 may be
                       // another test's
                       "--http-port", "0", "--rtsp-port", "0"},
                      log) {}
};

// True once the server answers (bounded).
bool WaitUntilServing(SlapseClient& c) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < deadline) {
    if (c.ListSessions(1, "", v1::Session::STATE_UNSPECIFIED).ok()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return false;
}

// Polls `name` (bounded) until `done` holds.
v1::Session WaitFor(SlapseClient& c, const std::string& name,
                    const std::function<bool(const v1::Session&)>& done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  v1::Session s;
  while (std::chrono::steady_clock::now() < deadline) {
    auto got = c.GetSession(name);
    if (got.ok()) {
      s = *got;
      if (done(s)) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return s;
}

// Events of `name` from the start until `count` were read (the session may
// still be active, so the watch is cut there).
std::vector<v1::SessionEvent> FirstEvents(SlapseClient& c, const std::string& name, size_t count) {
  std::vector<v1::SessionEvent> out;
  (void)c.Watch(name, 0, [&](const v1::SessionEvent& e) {
    out.push_back(e);
    return out.size() < count;
  });
  return out;
}

class PersistenceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::MakeTempDir("persistence_e2e");
    auto drive =
        testing::SimulateTestDrive("persistence_drive", testing::SmallMpeg2DriveOptions(3, 2.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    drive_ = *drive;
    port_ = testing::FreeLoopbackTcpPort();
    ASSERT_GT(port_, 0);
  }

  std::unique_ptr<ServeProcess> Serve() {
    auto p = std::make_unique<ServeProcess>(port_, dir_ + "/data", dir_ + "/serve.log");
    client_ = SlapseClient::Connect("127.0.0.1:" + std::to_string(port_), TestClientOptions());
    EXPECT_TRUE(WaitUntilServing(*client_)) << "see " << dir_ << "/serve.log";
    return p;
  }

  v1::Session Request() const {
    v1::Session s;
    v1::Intrinsics* k = s.mutable_intrinsics();
    k->set_fx_px(drive_.intrinsics.fx_px);
    k->set_fy_px(drive_.intrinsics.fy_px);
    k->set_cx_px(drive_.intrinsics.cx_px);
    k->set_cy_px(drive_.intrinsics.cy_px);
    return s;
  }

  // A camera publishing the drive in a loop, in real time, to `url`.
  std::unique_ptr<FfmpegProcess> Camera(const std::string& url) {
    EXPECT_TRUE(WaitForLocalPort("tcp", PortOf(url), std::chrono::seconds(10)));
    return std::make_unique<FfmpegProcess>(
        std::vector<std::string>{"-re", "-stream_loop", "-1", "-i", drive_.video_path, "-c", "copy",
                                 "-f", "rtsp", "-rtsp_transport", "tcp", url});
  }

  std::string dir_;
  testing::TestDrive drive_;
  int port_ = 0;
  std::unique_ptr<SlapseClient> client_;
};

void ExpectSameEvents(const std::vector<v1::SessionEvent>& before,
                      const std::vector<v1::SessionEvent>& after) {
  ASSERT_GE(after.size(), before.size());
  for (size_t i = 0; i < before.size(); ++i) {
    EXPECT_EQ(after[i].SerializeAsString(), before[i].SerializeAsString()) << "event " << i + 1;
  }
}

TEST_F(PersistenceTest, KillNineThenCleanStopLoseNothingCommitted) {
  auto server = Serve();
  // A: an upload that finished.
  v1::Session req = Request();
  req.mutable_upload();
  auto a = client_->CreateSession(req);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(client_->UploadFile(a->name(), drive_.video_path).ok());
  const v1::Session a_end = WaitFor(*client_, a->name(), [](const v1::Session& s) {
    return s.state() != v1::Session::CREATED && s.state() != v1::Session::RUNNING;
  });
  ASSERT_EQ(a_end.state(), v1::Session::FINISHED);
  auto a_traj = client_->GetTrajectory(a->name());
  ASSERT_TRUE(a_traj.ok());
  const auto a_events = FirstEvents(*client_, a->name(), a_end.last_sequence());
  ASSERT_EQ(a_events.size(), a_end.last_sequence());

  // B: an RTSP push camera, live.
  req = Request();
  req.mutable_rtsp_push()->set_path("cam");
  req.mutable_rtsp_push()->set_start_timeout_ms(60000);
  req.mutable_rtsp_push()->set_receive_timeout_ms(60000);
  auto b = client_->CreateSession(req);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  auto camera = Camera(testing::PublishUrl(*b));

  // C: an upload in flight (half the bytes sent, not half-closed).
  req = Request();
  req.mutable_upload();
  auto c = client_->CreateSession(req);
  ASSERT_TRUE(c.ok());
  auto channel =
      grpc::CreateChannel("127.0.0.1:" + std::to_string(port_), grpc::InsecureChannelCredentials());
  auto stub = v1::SlapseService::NewStub(channel);
  grpc::ClientContext upload_context;
  v1::Session upload_reply;
  auto writer = stub->UploadStream(&upload_context, &upload_reply);
  const std::string bytes = testing::ReadFileBytes(drive_.video_path);
  v1::UploadChunk chunk;
  chunk.set_name(c->name());
  chunk.set_data(bytes.substr(0, bytes.size() / 2));
  ASSERT_TRUE(writer->Write(chunk));
  WaitFor(*client_, c->name(), [](const v1::Session& s) { return s.stats().frames() > 0; });

  // Watch B until it streamed poses: whatever this watcher saw is committed.
  std::vector<v1::SessionEvent> b_seen;
  std::atomic<int> poses{0};
  std::thread watcher([&] {
    (void)client_->Watch(b->name(), 0, [&](const v1::SessionEvent& e) {
      b_seen.push_back(e);
      poses += e.has_pose();
      return true;  // until the server dies
    });
  });
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (poses < 10 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_GE(poses.load(), 10);
  server->Kill();  // SIGKILL, mid-stream
  watcher.join();
  camera.reset();
  writer.reset();

  // Restart on the same directory.
  server = Serve();
  auto list = client_->ListSessions(10, "", v1::Session::STATE_UNSPECIFIED);
  ASSERT_TRUE(list.ok());
  ASSERT_EQ(list->sessions_size(), 3);
  EXPECT_EQ(list->sessions(0).name(), a->name());  // creation order kept
  EXPECT_EQ(list->sessions(1).name(), b->name());
  EXPECT_EQ(list->sessions(2).name(), c->name());
  // A: as it was.
  auto a_again = client_->GetTrajectory(a->name());
  ASSERT_TRUE(a_again.ok());
  EXPECT_EQ(a_again->SerializeAsString(), a_traj->SerializeAsString());
  ExpectSameEvents(a_events, FirstEvents(*client_, a->name(), a_events.size() + 1));
  // B: every event seen before the kill, then "the server restarted" (CREATED).
  auto b_now = client_->GetSession(b->name());
  ASSERT_TRUE(b_now.ok());
  EXPECT_EQ(b_now->state(), v1::Session::CREATED) << b_now->state_message();
  EXPECT_NE(b_now->state_message().find("the server restarted"), std::string::npos);
  const auto b_after = FirstEvents(*client_, b->name(), b_now->last_sequence());
  ASSERT_GT(b_after.size(), b_seen.size());
  ExpectSameEvents(b_seen, b_after);
  EXPECT_EQ(b_after.back().state_change().state(), v1::Session::CREATED);
  // C: the interrupted upload says so.
  auto c_now = client_->GetSession(c->name());
  ASSERT_TRUE(c_now.ok());
  EXPECT_EQ(c_now->state(), v1::Session::FAILED);
  EXPECT_EQ(c_now->error().code(), static_cast<int>(StatusCode::kAborted));
  EXPECT_NE(c_now->error().message().find("the server restarted during the upload"),
            std::string::npos)
      << c_now->error().message();
  // New names are new.
  req = Request();
  req.mutable_upload();
  auto d = client_->CreateSession(req);
  ASSERT_TRUE(d.ok());
  for (const auto& old : {a->name(), b->name(), c->name()}) EXPECT_NE(d->name(), old);
  EXPECT_EQ(d->name().size(), std::string("sessions/").size() + 26);

  // B's camera comes back: B runs again, its new poses in segment 1.
  // The ingest URL names this run's RTSP port; the credentials shown at
  // creation still hold (they derive from the data directory's key).
  v1::Session b_publish = *b_now;
  *b_publish.mutable_publish_credentials() = b->publish_credentials();
  camera = Camera(testing::PublishUrl(b_publish));
  const v1::Session b_running = WaitFor(*client_, b->name(), [&](const v1::Session& s) {
    return s.stats().anchor_pairs() > b_now->stats().anchor_pairs() + 5;
  });
  EXPECT_EQ(b_running.state(), v1::Session::RUNNING);
  auto b_traj = client_->GetTrajectory(b->name());
  ASSERT_TRUE(b_traj.ok());
  std::map<int, int> per_segment;
  for (const auto& p : b_traj->points()) ++per_segment[p.segment()];
  EXPECT_GT(per_segment[0], 0);
  EXPECT_GT(per_segment[1], 0);

  // A clean stop (SIGTERM): B stays resumable, nothing lost.
  const auto b_before_stop = client_->GetSession(b->name());
  ASSERT_TRUE(b_before_stop.ok());
  const auto b_events_before_stop =
      FirstEvents(*client_, b->name(), b_before_stop->last_sequence());
  server->Signal(SIGTERM);
  EXPECT_EQ(server->Wait(std::chrono::seconds(30)), 0);
  camera.reset();
  server = Serve();
  b_now = client_->GetSession(b->name());
  ASSERT_TRUE(b_now.ok());
  EXPECT_EQ(b_now->state(), v1::Session::CREATED) << b_now->state_message();
  ExpectSameEvents(b_events_before_stop, FirstEvents(*client_, b->name(), b_now->last_sequence()));
  EXPECT_TRUE(client_->StopSession(b->name()).ok());
}

}  // namespace
}  // namespace slapse
