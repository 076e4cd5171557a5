// The dashboard's HTTP API against a real server on loopback (no browser):
// the access rules of the gRPC API (tokens, tenants, read-only, login
// cookie), redaction of camera credentials, protobuf's JSON mapping, the
// event stream's resume by Last-Event-ID, downloads and precise errors.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "api/convert.h"
#include "client/lib/client.h"
#include "core/common/json_io.h"
#include "server/server.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

// Last: httplib.h includes <resolv.h>, whose `_res` macro breaks Eigen's headers.
#include <httplib.h>

namespace slapse {
namespace {

constexpr char kTokenA[] = "token-of-acme-0123456789";
constexpr char kTokenB[] = "token-of-globex-0123456789";
constexpr char kTokenRo[] = "token-of-acme-readonly-0123";
constexpr char kSecret[] = "hunter2secret";

class DashboardApiTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto drive =
        testing::SimulateTestDrive("dashboard_api_drive", testing::SmallMpeg2DriveOptions(5, 2.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    drive_ = new testing::TestDrive(*drive);
  }
  static void TearDownTestSuite() { delete drive_; }

  void SetUp() override {
    const std::string dir = testing::MakeTempDir("dashboard_api");
    testing::WriteFileBytes(dir + "/tokens.json",
                            std::string("{\"tokens\": [") + "{\"token\": \"" + kTokenA +
                                "\", \"tenant\": \"acme\"}, {\"token\": \"" + kTokenB +
                                "\", \"tenant\": \"globex\"}, {\"token\": \"" + kTokenRo +
                                "\", \"tenant\": \"acme\", \"role\": \"read_only\"}]}");
    server::ServerOptions o;
    o.port = 0;
    o.http_port = server::ServerOptions::kAnyFreePort;
    o.auth.tokens_file = dir + "/tokens.json";
    o.shutdown_grace_s = 1;
    auto server = server::SlapseServer::Start(o);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    const std::string target = "127.0.0.1:" + std::to_string(server_->port());
    client::ClientOptions a = testing::TestClientOptions();
    a.token = kTokenA;
    a_ = client::SlapseClient::Connect(target, a);
    client::ClientOptions b = testing::TestClientOptions();
    b.token = kTokenB;
    b_ = client::SlapseClient::Connect(target, b);
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  // A finished upload session of acme's (or globex's with `b`).
  std::string FinishedUpload(client::SlapseClient* c) {
    v1::Session r;
    r.mutable_upload();
    *r.mutable_intrinsics() = api::IntrinsicsToProto(drive_->intrinsics);
    (*r.mutable_labels())["site"] = "north";
    auto s = c->CreateSession(r);
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    EXPECT_TRUE(c->UploadFile(s->name(), drive_->video_path).ok());
    for (int i = 0; i < 600; ++i) {
      auto got = c->GetSession(s->name());
      if (got.ok() && got->state() == v1::Session::FINISHED) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return s->name();
  }

  httplib::Result Get(const std::string& path, const std::string& token = "",
                      httplib::Headers headers = {}) {
    httplib::Client http("127.0.0.1", server_->http_port());
    http.set_read_timeout(20, 0);
    if (!token.empty()) headers.emplace("Authorization", std::string("Bearer ") + token);
    return http.Get(path, headers);
  }
  httplib::Result Post(const std::string& path, const std::string& token) {
    httplib::Client http("127.0.0.1", server_->http_port());
    return http.Post(path, httplib::Headers{{"Authorization", std::string("Bearer ") + token}}, "",
                     "application/x-www-form-urlencoded");
  }

  static testing::TestDrive* drive_;
  std::unique_ptr<server::SlapseServer> server_;
  std::unique_ptr<client::SlapseClient> a_, b_;
};
testing::TestDrive* DashboardApiTest::drive_ = nullptr;

std::string Q(const std::string& s) { return httplib::detail::encode_query_param(s); }

TEST_F(DashboardApiTest, NothingWithoutATokenAndNoSessionAcrossTenants) {
  const std::string a = FinishedUpload(a_.get());
  const std::string b = FinishedUpload(b_.get());
  // No token: every /api route is 401 with an ErrorStatus; the page is the login form.
  for (const std::string& path : std::vector<std::string>{
           "/api/sessions", "/api/session?name=" + Q(a), "/api/trajectory?name=" + Q(a),
           "/api/planes?name=" + Q(a), "/api/download?format=tum&name=" + Q(a),
           "/api/events?name=" + Q(a)}) {
    auto r = Get(path);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 401) << path;
    EXPECT_NE(r->body.find("\"code\":16"), std::string::npos) << path << ": " << r->body;
    EXPECT_EQ(r->body.find("sessions/"), std::string::npos) << path << ": " << r->body;
    EXPECT_EQ(Get(path, "not-a-token-but-long-enough")->status, 401) << path;
  }
  auto page = Get("/");
  ASSERT_TRUE(page);
  EXPECT_NE(page->body.find("action=\"/login\""), std::string::npos);
  EXPECT_EQ(page->body.find("fleet.js"), std::string::npos);

  // acme sees its session only; globex's is 404 as an unknown one.
  auto list = Get("/api/sessions", kTokenA);
  ASSERT_EQ(list->status, 200) << list->body;
  EXPECT_NE(list->body.find(a), std::string::npos);
  EXPECT_EQ(list->body.find(b), std::string::npos);
  for (const std::string path : {"/api/session?name=", "/api/trajectory?name=", "/api/planes?name=",
                                 "/api/events?name=", "/api/download?format=tum&name="}) {
    auto other = Get(path + Q(b), kTokenA);
    EXPECT_EQ(other->status, 404) << path << other->body;
    auto unknown = Get(path + Q("sessions/aaaaaaaaaaaaaaaaaaaaaaaaaa"), kTokenA);
    EXPECT_EQ(unknown->status, 404) << path;
  }
  EXPECT_EQ(Post("/api/stop?name=" + Q(b), kTokenA)->status, 404);
  EXPECT_EQ(Post("/api/delete?name=" + Q(b), kTokenA)->status, 404);
  EXPECT_TRUE(b_->GetSession(b).ok()) << "globex's session survives";
  // Read-only: may read, not stop or delete.
  EXPECT_EQ(Get("/api/session?name=" + Q(a), kTokenRo)->status, 200);
  EXPECT_EQ(Post("/api/delete?name=" + Q(a), kTokenRo)->status, 403);
  EXPECT_EQ(Post("/api/delete?name=" + Q(a), kTokenA)->status, 200);
  EXPECT_EQ(a_->GetSession(a).status().code(), StatusCode::kNotFound);
}

TEST_F(DashboardApiTest, LoginSetsAnHttpOnlyCookieThatAuthorizes) {
  const std::string a = FinishedUpload(a_.get());
  httplib::Client http("127.0.0.1", server_->http_port());
  auto bad = http.Post("/login", httplib::Params{{"token", "wrong-token-long-enough-123"}});
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->status, 303);
  EXPECT_FALSE(bad->has_header("Set-Cookie"));
  auto ok = http.Post("/login", httplib::Params{{"token", kTokenA}});
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->status, 303);
  const std::string cookie = ok->get_header_value("Set-Cookie");
  EXPECT_NE(cookie.find("HttpOnly"), std::string::npos) << cookie;
  EXPECT_NE(cookie.find("SameSite=Strict"), std::string::npos) << cookie;
  const std::string pair = cookie.substr(0, cookie.find(';'));
  auto list = Get("/api/sessions", "", {{"Cookie", "other=1; " + pair}});
  ASSERT_EQ(list->status, 200) << list->body;
  EXPECT_NE(list->body.find(a), std::string::npos);
  auto page = Get("/", "", {{"Cookie", pair}});
  EXPECT_NE(page->body.find("fleet.js"), std::string::npos);
}

TEST_F(DashboardApiTest, JsonIsProtobufsMappingAndFiltersAreTheListQuery) {
  const std::string a = FinishedUpload(a_.get());
  auto r = Get("/api/sessions?filter=" + Q("labels.site = \"north\" AND state = FINISHED") +
                   "&order_by=" + Q("stats.frames desc"),
               kTokenA);
  ASSERT_EQ(r->status, 200) << r->body;
  v1::ListSessionsResponse list;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(r->body, &list).ok()) << r->body;
  ASSERT_EQ(list.sessions_size(), 1);
  EXPECT_EQ(list.sessions(0).name(), a);
  EXPECT_EQ(list.sessions(0).labels().at("site"), "north");
  EXPECT_GT(list.sessions(0).stats().frames(), 10);
  EXPECT_EQ(Get("/api/sessions?filter=" + Q("labels.site = \"south\""), kTokenA)->body.find(a),
            std::string::npos);
  // A bad filter: 400 with the list query's message (column and expectation).
  auto bad = Get("/api/sessions?filter=" + Q("state = = RUNNING"), kTokenA);
  EXPECT_EQ(bad->status, 400);
  EXPECT_NE(bad->body.find("\"code\":3"), std::string::npos) << bad->body;
  EXPECT_NE(bad->body.find("column"), std::string::npos) << bad->body;
  EXPECT_EQ(Get("/api/sessions?state=SLEEPING", kTokenA)->status, 400);
  EXPECT_EQ(Get("/api/trajectory?page_size=ten&name=" + Q(a), kTokenA)->status, 400);
  EXPECT_EQ(Get("/api/download?format=png&name=" + Q(a), kTokenA)->status, 400);

  // The trajectory, paged as the store serves it, equals the gRPC one.
  auto grpc = a_->GetTrajectory(a);
  ASSERT_TRUE(grpc.ok());
  ASSERT_GT(grpc->points_size(), 10);
  int points = 0;
  std::string token;
  do {
    auto page =
        Get("/api/trajectory?page_size=7&name=" + Q(a) + "&page_token=" + Q(token), kTokenA);
    ASSERT_EQ(page->status, 200) << page->body;
    v1::Trajectory t;
    ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(page->body, &t).ok());
    EXPECT_LE(t.points_size(), 7);
    for (const auto& p : t.points()) {
      EXPECT_EQ(p.anchor_index(), grpc->points(points).anchor_index());
      EXPECT_DOUBLE_EQ(p.world_from_cam().tx(), grpc->points(points).world_from_cam().tx());
      ++points;
    }
    token = t.next_page_token();
  } while (!token.empty());
  EXPECT_EQ(points, grpc->points_size());

  // Downloads: TUM with a line per pose, as `slapse export` writes it.
  auto tum = Get("/api/download?format=tum&name=" + Q(a), kTokenA);
  ASSERT_EQ(tum->status, 200);
  int lines = 0;
  for (size_t i = 0; i < tum->body.size(); i = tum->body.find('\n', i) + 1) {
    if (tum->body[i] != '#') ++lines;
    if (tum->body.find('\n', i) == std::string::npos) break;
  }
  EXPECT_EQ(lines, grpc->points_size());
  EXPECT_NE(tum->get_header_value("Content-Disposition").find("attachment"), std::string::npos);
  auto json = Get("/api/download?format=json&name=" + Q(a), kTokenA);
  ASSERT_EQ(json->status, 200);
  EXPECT_TRUE(ParseJsonText(json->body, "download").ok());
}

// The server-sent events of a finished session, as raw text.
std::string ReadEvents(int port, const std::string& name, const httplib::Headers& headers) {
  httplib::Client http("127.0.0.1", port);
  http.set_read_timeout(20, 0);
  std::string body;
  auto r = http.Get("/api/events?name=" + Q(name), headers, [&](const char* data, size_t n) {
    body.append(data, n);
    return true;
  });
  return r && r->status == 200 ? body : "HTTP error";
}

// The `id:` lines of an event stream.
std::vector<uint64_t> Ids(const std::string& body) {
  std::vector<uint64_t> ids;
  for (size_t i = body.find("id: "); i != std::string::npos; i = body.find("\nid: ", i + 1)) {
    ids.push_back(std::stoull(body.substr(body.find("id: ", i) + 4)));
  }
  return ids;
}

TEST_F(DashboardApiTest, EventsResumeAfterLastEventIdWithNothingLostOrRepeated) {
  const std::string a = FinishedUpload(a_.get());
  const httplib::Headers auth = {{"Authorization", std::string("Bearer ") + kTokenA}};
  const std::string all = ReadEvents(server_->http_port(), a, auth);
  const std::vector<uint64_t> ids = Ids(all);
  ASSERT_GT(ids.size(), 10u) << all.substr(0, 500);
  for (size_t i = 0; i < ids.size(); ++i) EXPECT_EQ(ids[i], i + 1);
  EXPECT_NE(all.find("event: end"), std::string::npos);
  EXPECT_NE(all.find("\"emit_time\""), std::string::npos);  // protobuf's JSON names
  // A browser reconnecting with Last-Event-ID: k gets k+1 .. last.
  const uint64_t k = ids.size() / 2;
  httplib::Headers resume = auth;
  resume.emplace("Last-Event-ID", std::to_string(k));
  const std::vector<uint64_t> rest = Ids(ReadEvents(server_->http_port(), a, resume));
  ASSERT_EQ(rest.size(), ids.size() - k);
  EXPECT_EQ(rest.front(), k + 1);
  EXPECT_EQ(rest.back(), ids.back());
  resume.erase("Last-Event-ID");
  resume.emplace("Last-Event-ID", "x1");
  EXPECT_EQ(ReadEvents(server_->http_port(), a, resume), "HTTP error");
}

TEST_F(DashboardApiTest, CameraCredentialsNeverLeave) {
  v1::Session r;
  r.mutable_rtsp_pull()->set_url(std::string("rtsp://admin:") + kSecret + "@127.0.0.1:9/cam");
  r.mutable_rtsp_pull()->set_start_timeout_ms(200);
  *r.mutable_intrinsics() = api::IntrinsicsToProto(drive_->intrinsics);
  auto s = a_->CreateSession(r);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // let it fail and log why
  for (const std::string& path :
       std::vector<std::string>{"/api/sessions", "/api/session?name=" + Q(s->name())}) {
    auto got = Get(path, kTokenA);
    ASSERT_EQ(got->status, 200);
    EXPECT_NE(got->body.find("127.0.0.1:9"), std::string::npos) << got->body;
    EXPECT_EQ(got->body.find(kSecret), std::string::npos) << got->body;
  }
  ASSERT_TRUE(a_->StopSession(s->name()).ok());
  const httplib::Headers auth = {{"Authorization", std::string("Bearer ") + kTokenA}};
  const std::string events = ReadEvents(server_->http_port(), s->name(), auth);
  EXPECT_NE(events.find("event: end"), std::string::npos) << events;
  EXPECT_EQ(events.find(kSecret), std::string::npos) << events;
}

}  // namespace
}  // namespace slapse
