// A real Prometheus (Debian's `prometheus`) scrapes a real slapse server's
// /metrics: the test starts both on loopback (Prometheus with a temp config
// and data dir), then asks Prometheus' HTTP query API for slapse series until
// they arrive (or a generous deadline passes).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "api/convert.h"
#include "client/lib/client.h"
#include "core/common/json_io.h"
#include "server/server.h"
#include "tests/test_streams.h"

// Last: httplib.h includes <resolv.h>, whose `_res` macro breaks Eigen's headers.
#include <httplib.h>

namespace slapse {
namespace {

class PrometheusProcess : public testing::ChildProcess {
 public:
  PrometheusProcess(const std::string& dir, int web_port) {
    std::vector<std::string> argv = {"prometheus", "--config.file=" + dir + "/prometheus.yml",
                                     "--storage.tsdb.path=" + dir + "/data",
                                     "--web.listen-address=127.0.0.1:" + std::to_string(web_port),
                                     "--log.level=warn"};
    std::vector<char*> c;
    for (std::string& a : argv) c.push_back(a.data());
    c.push_back(nullptr);
    const std::string log = dir + "/prometheus.log";
    pid_ = fork();
    if (pid_ == 0) {
      const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      dup2(fd, 1);
      dup2(fd, 2);
      execvp("prometheus", c.data());
      _exit(127);
    }
  }
};

// The value of the first series `query` returns, if any yet.
std::optional<std::string> Query(int port, const std::string& query) {
  httplib::Client http("127.0.0.1", port);
  http.set_read_timeout(5, 0);
  auto res = http.Get("/api/v1/query", httplib::Params{{"query", query}}, httplib::Headers{});
  if (!res || res->status != 200) return std::nullopt;
  auto doc = ParseJsonText(res->body, "query response");
  if (!doc.ok()) return std::nullopt;
  const Json& result = (*doc)["data"]["result"];
  if (!result.is_array() || result.empty()) return std::nullopt;
  return result[0]["value"][1].get<std::string>();
}

TEST(PrometheusScrapeTest, PrometheusScrapesSlapseMetrics) {
  server::ServerOptions o;
  o.port = 0;
  o.http_port = server::ServerOptions::kAnyFreePort;
  auto server = server::SlapseServer::Start(o);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  // One session waiting for its upload: slapse_sessions{state="CREATED"} is 1.
  auto client = client::SlapseClient::Connect("127.0.0.1:" + std::to_string((*server)->port()));
  v1::Session request;
  request.mutable_upload();
  *request.mutable_intrinsics() =
      api::IntrinsicsToProto(Intrinsics::FromHorizontalFov(320, 240, 60.0));
  ASSERT_TRUE(client->CreateSession(request).ok());

  const std::string dir = testing::MakeTempDir("prometheus_scrape");
  testing::WriteFileBytes(dir + "/prometheus.yml",
                          "global:\n"
                          "  scrape_interval: 1s\n"
                          "scrape_configs:\n"
                          "  - job_name: slapse\n"
                          "    static_configs:\n"
                          "      - targets: ['127.0.0.1:" +
                              std::to_string((*server)->http_port()) + "']\n");
  const int web_port = testing::FreeLoopbackTcpPort();
  ASSERT_GT(web_port, 0);
  PrometheusProcess prometheus(dir, web_port);
  ASSERT_TRUE(prometheus.started());

  // Prometheus starts, scrapes every second and makes the sample queryable:
  // seconds here; the deadline only bounds a broken setup.
  std::optional<std::string> created, up;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(90);
  while (std::chrono::steady_clock::now() < deadline) {
    created = Query(web_port, "slapse_sessions{job=\"slapse\",state=\"CREATED\"}");
    up = Query(web_port, "up{job=\"slapse\"}");
    if (created && up) break;
    ASSERT_EQ(prometheus.Wait(std::chrono::milliseconds(0)), -1)
        << "prometheus exited: " << testing::ReadFileBytes(dir + "/prometheus.log");
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
  EXPECT_EQ(up, "1") << testing::ReadFileBytes(dir + "/prometheus.log");
  EXPECT_EQ(created, "1") << testing::ReadFileBytes(dir + "/prometheus.log");
}

}  // namespace
}  // namespace slapse
