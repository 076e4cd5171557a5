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
#include "slapse/v1/slapse.pb.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

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
           "/api/events?name=" + Q(a), "/api/overlay?kind=mv&name=" + Q(a)}) {
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
  for (const std::string path :
       {"/api/session?name=", "/api/trajectory?name=", "/api/planes?name=", "/api/events?name=",
        "/api/download?format=tum&name=", "/api/overlay?kind=planes&name="}) {
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

// Pixels of `picture` (BGR) whose channels differ by more than 100: the
// overlays' colours (red / blue arrows, plane dots), never the grey frame.
int ColouredPixels(const cv::Mat& picture) {
  int n = 0;
  for (int r = 0; r < picture.rows; ++r) {
    for (int c = 0; c < picture.cols; ++c) {
      const cv::Vec3b p = picture.at<cv::Vec3b>(r, c);
      const int hi = std::max({p[0], p[1], p[2]}), lo = std::min({p[0], p[1], p[2]});
      n += hi - lo > 100;
    }
  }
  return n;
}

TEST_F(DashboardApiTest, OverlaysShowTheNewestAnchorOnceSomeoneAsks) {
  v1::Session r;
  r.mutable_upload();
  *r.mutable_intrinsics() = api::IntrinsicsToProto(drive_->intrinsics);
  auto s = a_->CreateSession(r);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  const std::string q = "&name=" + Q(s->name());
  // Nothing is kept before anyone asks: 503 says why; asking makes the
  // runner keep the anchors from now on.
  auto early = Get("/api/overlay?kind=mv" + q, kTokenA);
  ASSERT_TRUE(early);
  EXPECT_EQ(early->status, 503) << early->body;
  EXPECT_NE(early->body.find("no frame kept yet"), std::string::npos) << early->body;
  // Bad parameters are 400 naming them.
  auto bad_kind = Get("/api/overlay?kind=depth" + q, kTokenA);
  EXPECT_EQ(bad_kind->status, 400);
  EXPECT_NE(bad_kind->body.find("'kind' must be mv or planes"), std::string::npos)
      << bad_kind->body;
  auto bad_width = Get("/api/overlay?kind=mv&max_width_px=2" + q, kTokenA);
  EXPECT_EQ(bad_width->status, 400);
  EXPECT_NE(bad_width->body.find("max_width_px"), std::string::npos) << bad_width->body;

  ASSERT_TRUE(a_->UploadFile(s->name(), drive_->video_path).ok());
  v1::Session done;
  for (int i = 0; i < 600 && done.state() != v1::Session::FINISHED; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (auto got = a_->GetSession(s->name()); got.ok()) done = *got;
  }
  ASSERT_EQ(done.state(), v1::Session::FINISHED) << done.state_message();
  ASSERT_GT(done.stats().planes(), 0);
  const int width = drive_->intrinsics.width_px, height = drive_->intrinsics.height_px;
  ASSERT_GT(width, 0);

  // The MV picture: the newest anchor with vectors, at the stream's size
  // (narrower than the default 640 px), the frame's luma behind red arrows.
  auto mv = Get("/api/overlay?kind=mv" + q, kTokenA);
  ASSERT_EQ(mv->status, 200) << mv->body;
  EXPECT_EQ(mv->get_header_value("Content-Type"), "image/png");
  const int64_t mv_frame = std::stoll(mv->get_header_value("X-Slapse-Frame"));
  EXPECT_GT(mv_frame, done.stats().frames() - 12) << "one of the last frames";
  EXPECT_LT(mv_frame, done.stats().frames());
  const cv::Mat mv_picture =
      cv::imdecode(std::vector<uchar>(mv->body.begin(), mv->body.end()), cv::IMREAD_COLOR);
  ASSERT_FALSE(mv_picture.empty());
  EXPECT_EQ(mv_picture.cols, std::min(width, 640));
  EXPECT_EQ(mv_picture.rows, std::min(width, 640) * height / width);
  EXPECT_GT(ColouredPixels(mv_picture), 200) << "arrows drawn";
  EXPECT_GT(std::stoi(mv->get_header_value("X-Slapse-Count")), 50) << "vectors of a P frame";
  cv::Scalar mean, stddev;
  cv::meanStdDev(mv_picture, mean, stddev);
  EXPECT_GT(stddev[1], 10.0) << "the frame's picture, not the grey of a missing luma";
  // Smaller on request.
  auto small = Get("/api/overlay?kind=mv&max_width_px=160" + q, kTokenA);
  ASSERT_EQ(small->status, 200);
  const cv::Mat small_picture =
      cv::imdecode(std::vector<uchar>(small->body.begin(), small->body.end()), cv::IMREAD_COLOR);
  EXPECT_EQ(small_picture.cols, 160);
  EXPECT_EQ(small->get_header_value("X-Slapse-Frame"), mv->get_header_value("X-Slapse-Frame"));

  // The planes picture: the last anchor pair's later anchor, an anchor of
  // the trajectory, with coloured dots when that pair had planes.
  auto planes = Get("/api/overlay?kind=planes" + q, kTokenA);
  ASSERT_EQ(planes->status, 200) << planes->body;
  const int64_t planes_frame = std::stoll(planes->get_header_value("X-Slapse-Frame"));
  EXPECT_GE(planes_frame, mv_frame);
  const cv::Mat planes_picture =
      cv::imdecode(std::vector<uchar>(planes->body.begin(), planes->body.end()), cv::IMREAD_COLOR);
  ASSERT_FALSE(planes_picture.empty());
  EXPECT_EQ(planes_picture.cols, mv_picture.cols);
  std::printf("overlays: mv frame %lld (%d coloured px), planes frame %lld (%d coloured px)\n",
              static_cast<long long>(mv_frame), ColouredPixels(mv_picture),
              static_cast<long long>(planes_frame), ColouredPixels(planes_picture));
  // Dots exactly when the pair had planes (the caption's white text aside).
  const int planes_drawn = std::stoi(planes->get_header_value("X-Slapse-Count"));
  if (planes_drawn > 0) {
    EXPECT_GT(ColouredPixels(planes_picture), 20 * planes_drawn) << "plane dots drawn";
  } else {
    EXPECT_EQ(ColouredPixels(planes_picture), 0) << "no planes, no dots";
  }

  // A session nobody asked about keeps nothing.
  const std::string other = FinishedUpload(a_.get());
  auto none = Get("/api/overlay?kind=mv&name=" + Q(other), kTokenA);
  EXPECT_EQ(none->status, 503) << none->body;
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

// With the gRPC port's certificate and key the HTTP port speaks HTTPS only
// (a certificate the test makes with openssl): the dashboard and /metrics
// over TLS, verified against that certificate; plain HTTP gets nothing; the
// login cookie is Secure.
TEST(DashboardHttpsTest, TheHttpPortSpeaksTlsWithTheGrpcCertificate) {
  const std::string dir = testing::MakeTempDir("dashboard_https");
  const std::string cert = dir + "/server.pem", key = dir + "/server.key";
  ASSERT_EQ(
      testing::RunCommand("openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 "
                          "-nodes -days 2 -subj /CN=localhost -addext "
                          "subjectAltName=IP:127.0.0.1,DNS:localhost -keyout " +
                          key + " -out " + cert + " >/dev/null 2>&1"),
      0);
  testing::WriteFileBytes(dir + "/tokens.json", std::string("{\"tokens\": [{\"token\": \"") +
                                                    kTokenA + "\", \"tenant\": \"acme\"}]}");
  server::ServerOptions o;
  o.port = 0;
  o.http_port = server::ServerOptions::kAnyFreePort;
  o.auth.tls_cert_file = cert;
  o.auth.tls_key_file = key;
  o.auth.tokens_file = dir + "/tokens.json";
  o.shutdown_grace_s = 1;
  auto server = server::SlapseServer::Start(o);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  const int port = (*server)->http_port();

  httplib::SSLClient https("127.0.0.1", port);
  https.set_ca_cert_path(cert.c_str());
  https.enable_server_certificate_verification(true);
  auto health = https.Get("/healthz");
  ASSERT_TRUE(health) << httplib::to_string(health.error());
  EXPECT_EQ(health->status, 200);
  EXPECT_EQ(https.Get("/api/sessions")->status, 401);
  auto list = https.Get("/api/sessions", {{"Authorization", std::string("Bearer ") + kTokenA}});
  ASSERT_TRUE(list);
  EXPECT_EQ(list->status, 200) << list->body;
  auto login = https.Post("/login", httplib::Params{{"token", kTokenA}});
  ASSERT_TRUE(login);
  EXPECT_NE(login->get_header_value("Set-Cookie").find("; Secure"), std::string::npos)
      << login->get_header_value("Set-Cookie");

  // Plain HTTP on the same port: no response.
  httplib::Client plain("127.0.0.1", port);
  plain.set_read_timeout(5, 0);
  auto refused = plain.Get("/healthz");
  EXPECT_FALSE(refused && refused->status == 200);
  (*server)->Shutdown();
}

}  // namespace
}  // namespace slapse
