// The dashboard in a real browser (issue 16): a real server on loopback with a
// live RTSP push camera (ffmpeg) and a finished upload, and Debian's headless
// Chromium driven by playwright-core (tests/web/dashboard.mjs): fleet rows and
// states, the filter box, sorting by keyboard, a session's trajectory growing
// live over server-sent events, the newest frame's MV and plane overlays
// loading and updating, the event stream cut and resumed from Last-Event-ID,
// downloads, stop and delete from the page; and with tokens on, the login
// form (a wrong token refused, the right one showing its tenant's sessions
// only). Screenshots go to the test's temp dir; load time and update latency
// are printed.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>

#include "api/convert.h"
#include "client/lib/client.h"
#include "server/server.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using testing::FfmpegProcess;

// Runs `command` through the shell; its exit status, its stdout in `out`.
int RunCapture(const std::string& command, std::string* out) {
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return -1;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) out->append(buf.data(), n);
  const int rc = pclose(pipe);
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// Ensures tests/web/node_modules holds playwright-core: tests/web/ensure-node-modules.sh
// (`npm ci` from the lockfile, once, under a lock; ctest runs it first as the
// dashboard_test.web_node_modules fixture, this covers running the binary alone).
void EnsureNodeModules(const std::string& web_dir) {
  std::string log;
  ASSERT_EQ(RunCapture("'" + web_dir + "/ensure-node-modules.sh' 2>&1", &log), 0) << log;
}

// Polls `name` until its state is terminal (bounded).
v1::Session WaitEnded(client::SlapseClient* client, const std::string& name) {
  v1::Session s;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < deadline) {
    auto got = client->GetSession(name);
    if (got.ok()) s = *got;
    if (got.ok() && s.state() >= v1::Session::FINISHED) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return s;
}

TEST(DashboardTest, BrowserShowsTheFleetALiveSessionAndStopsIt) {
  const std::string web_dir = SLAPSE_WEB_TEST_DIR;
  EnsureNodeModules(web_dir);
  auto drive =
      testing::SimulateTestDrive("dashboard_test_drive", testing::SmallMpeg2DriveOptions(3, 6.0));
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();

  server::ServerOptions o;
  o.port = 0;
  o.http_port = server::ServerOptions::kAnyFreePort;
  o.sessions.max_sessions = 3;
  o.shutdown_grace_s = 1;
  auto server = server::SlapseServer::Start(o);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  auto client = client::SlapseClient::Connect("127.0.0.1:" + std::to_string((*server)->port()),
                                              testing::TestClientOptions());
  v1::Session request;
  *request.mutable_intrinsics() = api::IntrinsicsToProto(drive->intrinsics);

  // The upload: the whole drive, to FINISHED.
  request.mutable_upload();
  (*request.mutable_labels())["site"] = "south";
  auto upload = client->CreateSession(request);
  ASSERT_TRUE(upload.ok()) << upload.status().ToString();
  ASSERT_TRUE(client->UploadFile(upload->name(), drive->video_path).ok());
  ASSERT_EQ(WaitEnded(client.get(), upload->name()).state(), v1::Session::FINISHED);

  // The live camera: publishes the drive over and over until the page stops it.
  request.mutable_rtsp_push()->set_path("cam1");
  request.mutable_rtsp_push()->set_start_timeout_ms(10000);
  request.mutable_rtsp_push()->set_receive_timeout_ms(5000);
  (*request.mutable_labels())["site"] = "north";
  (*request.mutable_labels())["camera"] = "cam-7";
  auto live = client->CreateSession(request);
  ASSERT_TRUE(live.ok()) << live.status().ToString();
  ASSERT_TRUE(testing::WaitForLocalPort("tcp", testing::PortOf(live->ingest_url()),
                                        std::chrono::seconds(5)));
  FfmpegProcess camera({"-re", "-stream_loop", "-1", "-i", drive->video_path, "-c", "copy", "-f",
                        "rtsp", "-rtsp_transport", "tcp", testing::PublishUrl(*live)});
  ASSERT_TRUE(camera.started());
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (std::chrono::steady_clock::now() < deadline) {
    auto got = client->GetSession(live->name());
    if (got.ok() && got->state() == v1::Session::RUNNING && got->stats().anchor_pairs() > 2) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }

  const std::string out_dir = testing::MakeTempDir("dashboard_test_screens");
  const std::string args =
      "{\"url\": \"http://127.0.0.1:" + std::to_string((*server)->http_port()) +
      "\", \"live\": \"" + live->name() + "\", \"upload\": \"" + upload->name() +
      "\", \"out\": \"" + out_dir + "\"}";
  std::string measured;
  const int rc = RunCapture("node '" + web_dir + "/dashboard.mjs' '" + args + "'", &measured);
  ASSERT_EQ(rc, 0) << "the browser run failed (its stderr is above)";
  std::printf("dashboard measurements: %s", measured.c_str());
  std::printf("screenshots: %s/dashboard-fleet.png, %s/dashboard-session.png\n", out_dir.c_str(),
              out_dir.c_str());
  EXPECT_NE(measured.find("update_latency_ms_median"), std::string::npos) << measured;
  for (const char* png : {"dashboard-fleet.png", "dashboard-session.png"}) {
    EXPECT_GT(std::filesystem::file_size(out_dir + "/" + png), 10000u) << png;
  }

  // The page's Stop and Delete reached the server: the live session is
  // STOPPED, the upload gone.
  const v1::Session stopped = WaitEnded(client.get(), live->name());
  EXPECT_EQ(stopped.state(), v1::Session::STOPPED) << stopped.state_message();
  EXPECT_GT(stopped.stats().frames(), 10);
  EXPECT_EQ(client->GetSession(upload->name()).status().code(), StatusCode::kNotFound);
  (*server)->Shutdown();
}

TEST(DashboardTest, LoginFormRefusesAWrongTokenAndShowsOnlyTheTenantsSessions) {
  const std::string web_dir = SLAPSE_WEB_TEST_DIR;
  EnsureNodeModules(web_dir);
  auto drive =
      testing::SimulateTestDrive("dashboard_login_drive", testing::SmallMpeg2DriveOptions(4, 2.0));
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  const std::string dir = testing::MakeTempDir("dashboard_login");
  const std::string token_a = "token-of-acme-0123456789", token_b = "token-of-globex-0123456789";
  testing::WriteFileBytes(dir + "/tokens.json", "{\"tokens\": [{\"token\": \"" + token_a +
                                                    "\", \"tenant\": \"acme\"}, {\"token\": \"" +
                                                    token_b + "\", \"tenant\": \"globex\"}]}");
  server::ServerOptions o;
  o.port = 0;
  o.http_port = server::ServerOptions::kAnyFreePort;
  o.auth.tokens_file = dir + "/tokens.json";
  o.shutdown_grace_s = 1;
  auto server = server::SlapseServer::Start(o);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  const std::string target = "127.0.0.1:" + std::to_string((*server)->port());
  std::string names[2];
  for (int i = 0; i < 2; ++i) {
    client::ClientOptions co = testing::TestClientOptions();
    co.token = i == 0 ? token_a : token_b;
    auto client = client::SlapseClient::Connect(target, co);
    v1::Session request;
    request.mutable_upload();
    *request.mutable_intrinsics() = api::IntrinsicsToProto(drive->intrinsics);
    auto s = client->CreateSession(request);
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    ASSERT_TRUE(client->UploadFile(s->name(), drive->video_path).ok());
    ASSERT_EQ(WaitEnded(client.get(), s->name()).state(), v1::Session::FINISHED);
    names[i] = s->name();
  }
  const std::string out_dir = testing::MakeTempDir("dashboard_login_screens");
  const std::string args =
      "{\"mode\": \"auth\", \"url\": \"http://127.0.0.1:" + std::to_string((*server)->http_port()) +
      "\", \"token\": \"" + token_a + "\", \"mine\": \"" + names[0] + "\", \"theirs\": \"" +
      names[1] + "\", \"out\": \"" + out_dir + "\"}";
  std::string measured;
  const int rc = RunCapture("node '" + web_dir + "/dashboard.mjs' '" + args + "'", &measured);
  ASSERT_EQ(rc, 0) << "the browser run failed (its stderr is above)";
  std::printf("login scenario: %s", measured.c_str());
  EXPECT_NE(measured.find("\"rows\""), std::string::npos) << measured;
  (*server)->Shutdown();
}

}  // namespace
}  // namespace slapse
