// The server's /metrics (server/metrics.h, server/http_server.h) and health:
// a real server on loopback runs a simulated drive uploaded by the real
// client; its /metrics, fetched over HTTP, shows the session's snapshot
// figures, the rpcs by status code, the watchers and the stage histograms,
// and passes `promtool check metrics`. `slapse health` asks the real gRPC
// health service per service name. Reflection is switchable.
#include <grpcpp/create_channel.h>
#include <grpcpp/generic/generic_stub.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <sstream>
#include <string>

#include "api/convert.h"
#include "client/lib/client.h"
#include "core/pipeline/frame_poses.h"
#include "server/server.h"
#include "tests/test_streams.h"

// Last: httplib.h includes <resolv.h>, whose `_res` macro breaks Eigen's headers.
#include <httplib.h>

namespace slapse {
namespace {

using server::ServerOptions;
using server::SlapseServer;

// The value of the sample whose name and labels are exactly `series`
// (e.g. slapse_sessions{state="FINISHED"}), if the exposition has it.
std::optional<double> Sample(const std::string& text, const std::string& series) {
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind(series + " ", 0) == 0) return std::stod(line.substr(series.size() + 1));
  }
  return std::nullopt;
}

std::unique_ptr<SlapseServer> StartServer(bool reflection = true) {
  ServerOptions o;
  o.port = 0;
  o.http_port = ServerOptions::kAnyFreePort;
  o.reflection = reflection;
  auto server = SlapseServer::Start(o);
  EXPECT_TRUE(server.ok()) << server.status().ToString();
  return server.ok() ? std::move(*server) : nullptr;
}

std::string Get(int port, const std::string& path, int* status = nullptr,
                std::string* content_type = nullptr) {
  httplib::Client http("127.0.0.1", port);
  http.set_read_timeout(10, 0);
  auto res = http.Get(path.c_str());
  if (!res) {
    ADD_FAILURE() << "GET " << path << ": " << httplib::to_string(res.error());
    return "";
  }
  if (status != nullptr) *status = res->status;
  if (content_type != nullptr) *content_type = res->get_header_value("Content-Type");
  return res->body;
}

client::ClientOptions ClientOptions() {
  client::ClientOptions o;
  o.rpc_timeout_s = 10;
  o.upload_timeout_s = 60;
  o.watch_timeout_s = 60;
  return o;
}

TEST(MetricsTest, SessionRpcsWatchersAndStagesOnMetrics) {
  auto drive = testing::SimulateTestDrive("metrics", testing::SmallMpeg2DriveOptions(11, 3.0));
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  ASSERT_GT(server->http_port(), 0);
  auto client =
      client::SlapseClient::Connect("127.0.0.1:" + std::to_string(server->port()), ClientOptions());

  // Before any session: every state is there, at 0.
  const std::string empty = Get(server->http_port(), "/metrics");
  EXPECT_EQ(Sample(empty, "slapse_sessions{state=\"CREATED\"}"), 0.0) << empty;
  EXPECT_EQ(Sample(empty, "slapse_watchers"), 0.0) << empty;
  // The store's size: its schema's pages before any session.
  const std::optional<double> store_empty = Sample(empty, "slapse_store_bytes");
  ASSERT_TRUE(store_empty.has_value()) << empty;
  EXPECT_GT(*store_empty, 0.0);
  EXPECT_EQ(*store_empty, static_cast<double>(server->sessions().StoreBytes()));

  // One bad request: an INVALID_ARGUMENT counted by method and code.
  v1::Session bad;
  bad.mutable_upload();
  EXPECT_FALSE(client->CreateSession(bad).ok());

  v1::Session request;
  request.mutable_upload();
  *request.mutable_intrinsics() = api::IntrinsicsToProto(drive->intrinsics);
  auto created = client->CreateSession(request);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string name = created->name();
  ASSERT_TRUE(client->UploadFile(name, drive->video_path).ok());
  // While the watch stream is open (inside its callback) /metrics counts it.
  std::optional<double> watchers_during_watch;
  v1::Session::State last = v1::Session::STATE_UNSPECIFIED;
  Status watched = client->Watch(name, 0, [&](const v1::SessionEvent& e) {
    if (!watchers_during_watch) {
      watchers_during_watch = Sample(Get(server->http_port(), "/metrics"), "slapse_watchers");
    }
    if (e.has_state_change()) last = e.state_change().state();
    return true;
  });
  ASSERT_TRUE(watched.ok()) << watched.ToString();
  ASSERT_EQ(last, v1::Session::FINISHED);
  EXPECT_EQ(watchers_during_watch, 1.0);
  auto session = client->GetSession(name);
  ASSERT_TRUE(session.ok());
  ASSERT_GT(session->stats().frames(), 0);

  int status = 0;
  std::string content_type;
  const std::string text = Get(server->http_port(), "/metrics", &status, &content_type);
  EXPECT_EQ(status, 200);
  EXPECT_EQ(content_type, server::kPrometheusContentType);
  EXPECT_EQ(Sample(text, "slapse_sessions{state=\"FINISHED\"}"), 1.0) << text;
  EXPECT_EQ(Sample(text, "slapse_sessions{state=\"RUNNING\"}"), 0.0);
  const std::string s = "{session=\"" + name + "\"}";
  EXPECT_EQ(Sample(text, "slapse_session_frames_total" + s), session->stats().frames());
  EXPECT_EQ(Sample(text, "slapse_session_anchor_pairs_total" + s), session->stats().anchor_pairs());
  EXPECT_EQ(Sample(text, "slapse_session_tracked_pairs_total" + s),
            session->stats().tracked_pairs());
  EXPECT_EQ(Sample(text, "slapse_session_planes" + s), session->stats().planes());
  EXPECT_EQ(Sample(text, "slapse_session_plane_steps_total" + s), session->stats().plane_steps());
  // Planes measured some of the tracked steps, never more than were tracked,
  // and the verdict is ScaleSupport's on those counts.
  EXPECT_GT(session->stats().plane_steps(), 0);
  EXPECT_LE(session->stats().plane_steps(), session->stats().tracked_pairs());
  EXPECT_EQ(
      session->stats().scale_support_weak(),
      (ScaleSupport{session->stats().tracked_pairs(), session->stats().plane_steps()}.Weak()));
  // Doubles are printed with 16 significant digits.
  EXPECT_NEAR(Sample(text, "slapse_session_fps" + s).value_or(-1), session->stats().fps(),
              1e-9 * session->stats().fps());
  EXPECT_EQ(Sample(text, "slapse_watchers"), 0.0);
  // The session's events, poses and planes are in the store now.
  EXPECT_GT(Sample(text, "slapse_store_bytes").value_or(0), *store_empty) << text;
  const std::string svc = "/slapse.v1.SlapseService/";
  EXPECT_EQ(Sample(text, "slapse_rpcs_total{code=\"INVALID_ARGUMENT\",method=\"" + svc +
                             "CreateSession\"}"),
            1.0)
      << text;
  EXPECT_EQ(Sample(text, "slapse_rpcs_total{code=\"OK\",method=\"" + svc + "CreateSession\"}"),
            1.0);
  EXPECT_EQ(Sample(text, "slapse_rpcs_total{code=\"OK\",method=\"" + svc + "UploadStream\"}"), 1.0);
  EXPECT_EQ(Sample(text, "slapse_rpcs_total{code=\"OK\",method=\"" + svc + "WatchSession\"}"), 1.0);
  // Stage histograms are the process's: at least this session's frames.
  for (const char* stage : {"read", "pipeline", "publish"}) {
    const auto count =
        Sample(text, std::string("slapse_stage_seconds_count{stage=\"") + stage + "\"}");
    ASSERT_TRUE(count.has_value()) << stage << "\n" << text;
    EXPECT_GE(*count, static_cast<double>(session->stats().frames())) << stage;
  }

  // The real output passes Prometheus' own checker.
  const std::string dir = testing::MakeTempDir("metrics");
  testing::WriteFileBytes(dir + "/metrics.txt", text);
  EXPECT_EQ(testing::RunCommand("promtool check metrics < " + dir + "/metrics.txt"), 0) << text;

  Get(server->http_port(), "/nope", &status);
  EXPECT_EQ(status, 404);
  EXPECT_EQ(Get(server->http_port(), "/healthz", &status), "ok\n");
  EXPECT_EQ(status, 200);
}

// A second server on a port in use fails, naming the port, instead of
// sharing it: the HTTP port, and the gRPC port (gRPC's default SO_REUSEPORT
// would let both listen, each taking part of the connections).
TEST(MetricsTest, PortsInUseAreUnavailable) {
  auto first = StartServer();
  ASSERT_NE(first, nullptr);
  auto expect_unavailable = [](const ServerOptions& o, int port) {
    auto second = SlapseServer::Start(o);
    ASSERT_FALSE(second.ok()) << "port " << port;
    EXPECT_EQ(second.status().code(), StatusCode::kUnavailable);
    EXPECT_NE(second.status().message().find(std::to_string(port)), std::string::npos)
        << second.status().message();
  };
  ServerOptions o;
  o.port = 0;
  o.http_port = first->http_port();
  expect_unavailable(o, first->http_port());
  ServerOptions g;
  g.port = first->port();
  expect_unavailable(g, first->port());
  o.http_port = 70000;
  EXPECT_EQ(SlapseServer::Start(o).status().code(), StatusCode::kInvalidArgument);
}

int Health(int port, const std::string& service) {
  return testing::RunCommand(std::string(SLAPSE_CLI) +
                             " health --server 127.0.0.1:" + std::to_string(port) + " --service '" +
                             service + "' --timeout-s 5 >/dev/null 2>&1");
}

TEST(MetricsTest, HealthCliPerServiceName) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  const int port = server->port();
  EXPECT_EQ(Health(port, ""), 0);
  EXPECT_EQ(Health(port, "slapse.v1.SlapseService"), 0);
  EXPECT_EQ(Health(port, "no.such.Service"), 1);
  server->Shutdown();
  EXPECT_EQ(Health(port, "slapse.v1.SlapseService"), 1);
}

// The reflection service lists the server's services, or is UNIMPLEMENTED
// when switched off. The request is encoded by hand (the reflection protos
// are not installed by Debian's gRPC): field 7, list_services = "".
std::string ListServicesByReflection(int port, grpc::StatusCode* code) {
  auto channel =
      grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  grpc::CompletionQueue cq;
  auto call = stub.PrepareCall(
      &context, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  void* tag = nullptr;
  bool ok = false;
  auto step = [&](int t) { return cq.Next(&tag, &ok) && tag == reinterpret_cast<void*>(t) && ok; };
  call->StartCall(reinterpret_cast<void*>(1));
  std::string body;
  if (step(1)) {
    const std::string request("\x3a\x00", 2);
    grpc::Slice slice(request);
    grpc::ByteBuffer out(&slice, 1);
    call->Write(out, reinterpret_cast<void*>(2));
    if (step(2)) {
      call->WritesDone(reinterpret_cast<void*>(5));
      (void)step(5);
    }
  }
  grpc::ByteBuffer in;
  call->Read(&in, reinterpret_cast<void*>(3));
  if (cq.Next(&tag, &ok) && ok) {
    std::vector<grpc::Slice> slices;
    (void)in.Dump(&slices);
    for (const auto& s : slices) body.append(reinterpret_cast<const char*>(s.begin()), s.size());
  }
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(4));
  (void)cq.Next(&tag, &ok);
  *code = status.error_code();
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
  return body;
}

TEST(MetricsTest, ReflectionIsSwitchable) {
  grpc::StatusCode code = grpc::StatusCode::UNKNOWN;
  {
    auto on = StartServer(true);
    ASSERT_NE(on, nullptr);
    const std::string listed = ListServicesByReflection(on->port(), &code);
    EXPECT_EQ(code, grpc::StatusCode::OK);
    EXPECT_NE(listed.find("slapse.v1.SlapseService"), std::string::npos);
  }
  auto off = StartServer(false);
  ASSERT_NE(off, nullptr);
  EXPECT_EQ(ListServicesByReflection(off->port(), &code), "");
  EXPECT_EQ(code, grpc::StatusCode::UNIMPLEMENTED);
}

}  // namespace
}  // namespace slapse
