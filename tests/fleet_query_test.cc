// Fleet labels and ListSessions queries against a real server on loopback:
// labels set at creation come back everywhere, the codec is filled once the
// stream opens, the filter / order_by reach the server and a bad one is
// INVALID_ARGUMENT naming the column; the CLI's `list --filter` prints the
// matching sessions and refuses a bad expression with exit status 2.
#include <gtest/gtest.h>

#include <memory>
#include <set>
#include <string>

#include "client/lib/client.h"
#include "server/server.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::SlapseClient;

class FleetQueryTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto drive =
        testing::SimulateTestDrive("fleet_query_drive", testing::SmallMpeg2DriveOptions(5, 1.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    drive_ = *drive;
    server::ServerOptions o;
    o.address = "127.0.0.1";
    o.port = 0;
    o.sessions.max_sessions = 4;
    o.shutdown_grace_s = 1;
    auto server = server::SlapseServer::Start(o);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    target_ = "127.0.0.1:" + std::to_string(server_->port());
    client_ = SlapseClient::Connect(target_, testing::TestClientOptions());
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  StatusOr<v1::Session> Create(const std::string& site, const std::string& camera) {
    v1::Session s;
    s.mutable_upload();
    v1::Intrinsics* k = s.mutable_intrinsics();
    k->set_fx_px(drive_.intrinsics.fx_px);
    k->set_fy_px(drive_.intrinsics.fy_px);
    k->set_cx_px(drive_.intrinsics.cx_px);
    k->set_cy_px(drive_.intrinsics.cy_px);
    (*s.mutable_labels())["site"] = site;
    (*s.mutable_labels())["camera"] = camera;
    return client_->CreateSession(s);
  }

  std::set<std::string> Names(const std::string& filter, const std::string& order_by = "") {
    v1::ListSessionsRequest r;
    r.set_filter(filter);
    r.set_order_by(order_by);
    auto page = client_->ListSessions(r);
    EXPECT_TRUE(page.ok()) << page.status().ToString();
    std::set<std::string> out;
    if (page.ok()) {
      for (const auto& s : page->sessions()) out.insert(s.name());
    }
    return out;
  }

  testing::TestDrive drive_;
  std::unique_ptr<server::SlapseServer> server_;
  std::string target_;
  std::unique_ptr<SlapseClient> client_;
};

TEST_F(FleetQueryTest, LabelsCodecFilterAndOrderReachTheServer) {
  auto depot = Create("depot", "gate-1");
  auto harbour = Create("harbour", "crane-2");
  ASSERT_TRUE(depot.ok()) << depot.status().ToString();
  ASSERT_TRUE(harbour.ok()) << harbour.status().ToString();
  EXPECT_EQ(depot->labels().at("camera"), "gate-1");
  EXPECT_TRUE(depot->stream_report().codec().empty());  // no stream yet

  // The depot camera streams; its codec appears once the stream opens.
  auto uploaded = client_->UploadFile(depot->name(), drive_.video_path);
  ASSERT_TRUE(uploaded.ok()) << uploaded.status().ToString();
  // The upload returns once the bytes are buffered; watch to the end.
  Status watched = client_->Watch(depot->name(), 0, [](const v1::SessionEvent&) { return true; });
  EXPECT_TRUE(watched.ok()) << watched.ToString();
  auto got = client_->GetSession(depot->name());
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->state(), v1::Session::FINISHED) << got->state_message();
  EXPECT_EQ(got->stream_report().codec(), "mpeg2video");
  EXPECT_EQ(got->labels().at("site"), "depot");

  EXPECT_EQ(Names("labels.site=depot"), std::set<std::string>{depot->name()});
  EXPECT_EQ(Names("labels.camera=crane*"), std::set<std::string>{harbour->name()});
  EXPECT_EQ(Names("codec=mpeg2video"), std::set<std::string>{depot->name()});
  EXPECT_EQ(Names("state=CREATED"), std::set<std::string>{harbour->name()});
  EXPECT_EQ(Names("source=upload"), (std::set<std::string>{depot->name(), harbour->name()}));
  EXPECT_TRUE(Names("labels.site=nowhere").empty());

  v1::ListSessionsRequest ordered;
  ordered.set_order_by("labels.site desc");
  auto page = client_->ListSessions(ordered);
  ASSERT_TRUE(page.ok());
  ASSERT_EQ(page->sessions_size(), 2);
  EXPECT_EQ(page->sessions(0).name(), harbour->name());

  v1::ListSessionsRequest bad;
  bad.set_filter("labels.site=depot AND colour=red");
  auto refused = client_->ListSessions(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("unknown field 'colour' at column 23"),
            std::string::npos)
      << refused.status().message();

  // A bad label at creation: INVALID_ARGUMENT, nothing created.
  auto third = Create("depot", "gate-1");
  ASSERT_TRUE(third.ok());
  v1::Session upper;
  upper.mutable_upload();
  *upper.mutable_intrinsics() = got->intrinsics();
  (*upper.mutable_labels())["Site"] = "x";
  auto refused_label = client_->CreateSession(upper);
  EXPECT_EQ(refused_label.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused_label.status().message().find("labels"), std::string::npos);
  EXPECT_EQ(Names("").size(), 3u);

  // The CLI: the query goes through; a bad expression is a usage error (2).
  const std::string cli = SLAPSE_CLI;
  const std::string out_path = testing::MakeTempDir("fleet_query_cli") + "/list.txt";
  ASSERT_EQ(testing::RunCommand(cli + " list --server " + target_ +
                                " --filter 'labels.camera=crane-2' >" + out_path + " 2>&1"),
            0);
  const std::string out = testing::ReadFileBytes(out_path);
  EXPECT_NE(out.find(harbour->name()), std::string::npos) << out;
  EXPECT_EQ(out.find(depot->name()), std::string::npos) << out;
  EXPECT_NE(out.find("camera=crane-2"), std::string::npos) << out;
  EXPECT_EQ(
      testing::RunCommand(cli + " list --server " + target_ + " --filter 'state=' >/dev/null 2>&1"),
      2);
}

}  // namespace
}  // namespace slapse
