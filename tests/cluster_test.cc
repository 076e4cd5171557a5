// A local slapse cluster: three real `slapse serve` replicas (each with its
// own data directory, --replica-id and --peers) behind a real HAProxy whose
// configuration is deploy/k8s/haproxy-cfg.sh's output, all on loopback, with
// bearer tokens on (so the ListSessions fan-out must forward the caller's
// token). Everything goes through the proxy: sessions spread over the
// replicas, upload / watch / export / stop / delete reach the owner (checked
// on the replicas directly), ListSessions sees every replica; a replica
// killed with SIGKILL makes exactly its sessions UNAVAILABLE (naming it)
// while the others serve, and restarted on its store it has them back.
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "api/session_name.h"
#include "client/lib/client.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::SlapseClient;
using testing::TestClientOptions;

constexpr int kReplicas = 3;
constexpr int kSessions = 6;
const char* const kToken = "acme-token-0123456789abcdef";
const char* const kOtherToken = "globex-token-0123456789abcdef";

// Runs `command` and returns its stdout ("" on failure).
std::string Capture(const std::string& command) {
  std::string out;
  FILE* p = popen(command.c_str(), "r");
  if (p == nullptr) return out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  return pclose(p) == 0 ? out : "";
}

// Polls `done` every 100 ms until it holds or 30 s passed; its last value.
bool Eventually(const std::function<bool()>& done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (std::chrono::steady_clock::now() < deadline) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return done();
}

// Median wall time of `call` over 21 runs, ms. Printed, never asserted.
double MedianMs(const std::function<void()>& call) {
  std::vector<double> ms;
  for (int i = 0; i < 21; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    call();
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

client::ClientOptions WithToken(const std::string& token) {
  client::ClientOptions o = TestClientOptions();
  o.token = token;
  return o;
}

class ClusterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_EQ(access(SLAPSE_HAPROXY, X_OK), 0)
        << "haproxy not found (" << SLAPSE_HAPROXY << "): bash deploy/install-deps.sh";
    dir_ = testing::MakeTempDir("cluster_test");
    auto drive =
        testing::SimulateTestDrive("cluster_drive", testing::SmallMpeg2DriveOptions(5, 2.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    drive_ = *drive;
    std::ofstream(dir_ + "/tokens.json")
        << R"({"tokens": [{"token": ")" << kToken << R"(", "tenant": "acme"},)"
        << R"({"token": ")" << kOtherToken << R"(", "tenant": "globex"}]})";
    std::string replicas, peers;
    for (int i = 0; i < kReplicas; ++i) {
      ports_.push_back(testing::FreeLoopbackTcpPort());
      ids_.push_back("slapse-" + std::to_string(i));
      replicas += " " + ids_[i] + "=127.0.0.1:" + std::to_string(ports_[i]);
      peers += (i ? "," : "") + Address(i);
    }
    peers_ = peers;
    proxy_port_ = testing::FreeLoopbackTcpPort();
    const std::string cfg = Capture(std::string(SLAPSE_HAPROXY_CFG) +
                                    " --bind 127.0.0.1:" + std::to_string(proxy_port_) + replicas);
    ASSERT_FALSE(cfg.empty()) << "haproxy-cfg.sh failed";
    std::ofstream(dir_ + "/haproxy.cfg") << cfg;
    ASSERT_EQ(
        std::system((std::string(SLAPSE_HAPROXY) + " -c -q -f " + dir_ + "/haproxy.cfg").c_str()),
        0)
        << "haproxy -c rejects " << dir_ << "/haproxy.cfg";
    for (int i = 0; i < kReplicas; ++i) replicas_.push_back(Serve(i));
    proxy_ = std::make_unique<testing::LoggedProcess>(
        std::vector<std::string>{SLAPSE_HAPROXY, "-db", "-f", dir_ + "/haproxy.cfg"},
        dir_ + "/haproxy.log");
    client_ = SlapseClient::Connect(ProxyAddress(), WithToken(kToken));
    for (int i = 0; i < kReplicas; ++i) {
      ASSERT_TRUE(Eventually([&] { return ReachesReplica(i); }))
          << ids_[i] << " not reachable through the proxy; see " << dir_;
    }
  }

  std::string Address(int i) const { return "127.0.0.1:" + std::to_string(ports_[i]); }
  std::string ProxyAddress() const { return "127.0.0.1:" + std::to_string(proxy_port_); }

  std::unique_ptr<testing::LoggedProcess> Serve(int i) {
    return std::make_unique<testing::LoggedProcess>(
        std::vector<std::string>{SLAPSE_CLI,         "serve",
                                 "--address",        "127.0.0.1",
                                 "--port",           std::to_string(ports_[i]),
                                 "--http-port",      "0",
                                 "--rtsp-port",      "0",  // 8554 would collide
                                 "--data-dir",       dir_ + "/data-" + ids_[i],
                                 "--max-sessions",   "4",
                                 "--replica-id",     ids_[i],
                                 "--peers",          peers_,
                                 "--peer-timeout-s", "5",
                                 "--tokens-file",    dir_ + "/tokens.json"},
        dir_ + "/" + ids_[i] + ".log");
  }

  // A made-up session name of replica i.
  std::string Unknown(int i) const {
    return api::MakeSessionName(ids_[i], "aaaaaaaaaaaaaaaaaaaaaaaaaa");
  }

  // True once a call about replica i's sessions reaches replica i through
  // the proxy (the replica itself answers NOT_FOUND "on this server").
  bool ReachesReplica(int i) {
    auto s = client_->GetSession(Unknown(i));
    return s.status().code() == StatusCode::kNotFound &&
           s.status().message().find("on this server") != std::string::npos &&
           s.status().message().find("belongs to") == std::string::npos;
  }

  int ReplicaIndex(const std::string& session) const {
    const std::string id = api::SessionReplica(session);
    for (int i = 0; i < kReplicas; ++i) {
      if (ids_[i] == id) return i;
    }
    return -1;
  }

  v1::Session UploadRequest() const {
    v1::Session s;
    v1::Intrinsics* k = s.mutable_intrinsics();
    k->set_fx_px(drive_.intrinsics.fx_px);
    k->set_fy_px(drive_.intrinsics.fy_px);
    k->set_cx_px(drive_.intrinsics.cx_px);
    k->set_cy_px(drive_.intrinsics.cy_px);
    s.mutable_upload();
    return s;
  }

  std::string dir_;
  testing::TestDrive drive_;
  std::vector<int> ports_;
  std::vector<std::string> ids_;
  std::string peers_;
  int proxy_port_ = 0;
  std::vector<std::unique_ptr<testing::LoggedProcess>> replicas_;
  std::unique_ptr<testing::LoggedProcess> proxy_;
  std::unique_ptr<SlapseClient> client_;
};

// Every name of a ListSessions through `c`, all pages of `page_size`.
std::vector<std::string> ListAll(SlapseClient& c, int page_size,
                                 std::vector<std::string>* unreachable = nullptr) {
  std::vector<std::string> names;
  v1::ListSessionsRequest request;
  request.set_page_size(page_size);
  do {
    auto page = c.ListSessions(request);
    EXPECT_TRUE(page.ok()) << page.status().ToString();
    if (!page.ok()) break;
    for (const auto& s : page->sessions()) names.push_back(s.name());
    if (unreachable != nullptr) {
      for (const auto& u : page->unreachable_peers()) unreachable->push_back(u);
    }
    request.set_page_token(page->next_page_token());
  } while (!request.page_token().empty());
  return names;
}

TEST_F(ClusterTest, RoutesByOwnerListsAllAndSurvivesAReplicaKilled) {
  // Sessions created through the proxy spread over the replicas.
  std::vector<std::string> names;
  std::set<std::string> owners;
  for (int k = 0; k < kSessions; ++k) {
    auto s = client_->CreateSession(UploadRequest());
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    ASSERT_GE(ReplicaIndex(s->name()), 0) << s->name();
    names.push_back(s->name());
    owners.insert(api::SessionReplica(s->name()));
  }
  EXPECT_GE(owners.size(), 2u);

  // Upload, watch to the end and export, all through the proxy, in parallel.
  std::vector<std::thread> drives;
  std::vector<Status> uploaded(kSessions), watched(kSessions);
  std::vector<v1::Session::State> last_state(kSessions);
  for (int k = 0; k < kSessions; ++k) {
    drives.emplace_back([&, k] {
      auto c = SlapseClient::Connect(ProxyAddress(), WithToken(kToken));
      uploaded[k] = c->UploadFile(names[k], drive_.video_path).status();
      watched[k] = c->Watch(names[k], 0, [&](const v1::SessionEvent& e) {
        if (e.has_state_change()) last_state[k] = e.state_change().state();
        return true;
      });
    });
  }
  for (auto& t : drives) t.join();
  std::map<std::string, std::string> trajectories;
  for (int k = 0; k < kSessions; ++k) {
    EXPECT_TRUE(uploaded[k].ok()) << names[k] << ": " << uploaded[k].ToString();
    EXPECT_TRUE(watched[k].ok()) << names[k] << ": " << watched[k].ToString();
    EXPECT_EQ(last_state[k], v1::Session::FINISHED) << names[k];
    auto t = client_->GetTrajectory(names[k]);
    ASSERT_TRUE(t.ok()) << t.status().ToString();
    EXPECT_GT(t->points_size(), 10) << names[k];
    trajectories[names[k]] = t->SerializeAsString();
    // The owner holds it; another replica, asked directly, says whose it is.
    const int owner = ReplicaIndex(names[k]);
    auto direct = SlapseClient::Connect(Address(owner), WithToken(kToken));
    auto on_owner = direct->GetSession(names[k]);
    ASSERT_TRUE(on_owner.ok()) << on_owner.status().ToString();
    EXPECT_EQ(on_owner->state(), v1::Session::FINISHED);
    auto other = SlapseClient::Connect(Address((owner + 1) % kReplicas), WithToken(kToken));
    auto misrouted = other->GetSession(names[k]);
    EXPECT_EQ(misrouted.status().code(), StatusCode::kNotFound);
    EXPECT_NE(misrouted.status().message().find("belongs to replica '" + ids_[owner] + "'"),
              std::string::npos)
        << misrouted.status().message();
  }

  // ListSessions through the proxy sees every replica: all pages, any page
  // size, the same set; ordered across replicas; filtered; per tenant.
  std::vector<std::string> unreachable;
  std::vector<std::string> listed = ListAll(*client_, 4, &unreachable);
  EXPECT_TRUE(unreachable.empty()) << unreachable.front();
  EXPECT_EQ(std::set<std::string>(listed.begin(), listed.end()),
            std::set<std::string>(names.begin(), names.end()));
  EXPECT_EQ(listed.size(), names.size());  // no session twice across pages
  EXPECT_EQ(listed, ListAll(*client_, 1000));
  v1::ListSessionsRequest by_name;
  by_name.set_order_by("name desc");
  by_name.set_filter("state=FINISHED");
  auto ordered = client_->ListSessions(by_name);
  ASSERT_TRUE(ordered.ok()) << ordered.status().ToString();
  ASSERT_EQ(ordered->sessions_size(), kSessions);
  for (int k = 1; k < kSessions; ++k) {
    EXPECT_GT(ordered->sessions(k - 1).name(), ordered->sessions(k).name());
  }
  auto other_tenant = SlapseClient::Connect(ProxyAddress(), WithToken(kOtherToken));
  std::vector<std::string> theirs_unreachable;
  EXPECT_TRUE(ListAll(*other_tenant, 10, &theirs_unreachable).empty());
  EXPECT_TRUE(theirs_unreachable.empty());

  // What the proxy hop and the fan-out cost (printed for docs/DEPLOY.md).
  {
    const int owner = ReplicaIndex(names[0]);
    auto direct = SlapseClient::Connect(Address(owner), WithToken(kToken));
    auto stub = v1::SlapseService::NewStub(
        grpc::CreateChannel(Address(owner), grpc::InsecureChannelCredentials()));
    const double get_proxy = MedianMs([&] { (void)client_->GetSession(names[0]); });
    const double get_direct = MedianMs([&] { (void)direct->GetSession(names[0]); });
    const double list_proxy = MedianMs([&] { (void)ListAll(*client_, 50); });
    const double list_local = MedianMs([&] {
      grpc::ClientContext context;
      context.AddMetadata("authorization", std::string("Bearer ") + kToken);
      context.AddMetadata(api::kFanoutHeader, api::kFanoutLocal);
      v1::ListSessionsRequest request;
      v1::ListSessionsResponse response;
      (void)stub->ListSessions(&context, request, &response);
    });
    std::printf(
        "cluster-timing: median of 21, ms: GetSession via proxy %.2f, direct %.2f; "
        "ListSessions (%d sessions) via proxy with fan-out over %d replicas %.2f, one replica's "
        "own %.2f\n",
        get_proxy, get_direct, kSessions, kReplicas, list_proxy, list_local);
  }

  // Stop and delete reach the owner.
  auto live = client_->CreateSession(UploadRequest());
  ASSERT_TRUE(live.ok()) << live.status().ToString();
  auto stopped = client_->StopSession(live->name());
  ASSERT_TRUE(stopped.ok()) << stopped.status().ToString();
  EXPECT_EQ(stopped->state(), v1::Session::STOPPED);
  ASSERT_TRUE(client_->DeleteSession(live->name()).ok());
  EXPECT_EQ(client_->GetSession(live->name()).status().code(), StatusCode::kNotFound);

  // Kill -9 the owner of the first session.
  const int victim = ReplicaIndex(names[0]);
  replicas_[victim]->Kill();
  const auto killed = std::chrono::steady_clock::now();
  // Its sessions: UNAVAILABLE naming it (once the proxy's check saw it go).
  ASSERT_TRUE(Eventually([&] {
    auto s = client_->GetSession(names[0]);
    return s.status().code() == StatusCode::kUnavailable &&
           s.status().message().find("replica " + ids_[victim]) != std::string::npos;
  })) << client_->GetSession(names[0]).status().ToString();
  std::printf(
      "cluster-timing: kill -9 -> its sessions UNAVAILABLE naming it: %.0f ms\n",
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - killed).count());
  std::vector<std::string> survivors;
  for (int k = 0; k < kSessions; ++k) {
    if (ReplicaIndex(names[k]) == victim) {
      const Status s = client_->GetTrajectory(names[k]).status();
      EXPECT_EQ(s.code(), StatusCode::kUnavailable) << s.ToString();
      EXPECT_NE(s.message().find(ids_[victim]), std::string::npos) << s.ToString();
    } else {
      survivors.push_back(names[k]);
      auto t = client_->GetTrajectory(names[k]);
      ASSERT_TRUE(t.ok()) << names[k] << ": " << t.status().ToString();
      EXPECT_EQ(t->SerializeAsString(), trajectories[names[k]]);
    }
  }
  // New sessions land on the others; the list names the missing replica.
  auto fresh = client_->CreateSession(UploadRequest());
  ASSERT_TRUE(fresh.ok()) << fresh.status().ToString();
  EXPECT_NE(ReplicaIndex(fresh->name()), victim);
  survivors.push_back(fresh->name());
  unreachable.clear();
  listed = ListAll(*client_, 50, &unreachable);
  EXPECT_EQ(std::set<std::string>(listed.begin(), listed.end()),
            std::set<std::string>(survivors.begin(), survivors.end()));
  ASSERT_EQ(unreachable.size(), 1u);
  EXPECT_EQ(unreachable[0].rfind(Address(victim) + ": UNAVAILABLE", 0), 0u) << unreachable[0];

  // Restarted on its store: its sessions are back as they were.
  replicas_[victim] = Serve(victim);
  const auto restarted = std::chrono::steady_clock::now();
  ASSERT_TRUE(Eventually([&] { return ReachesReplica(victim); })) << "see " << dir_;
  std::printf(
      "cluster-timing: restart -> reachable through the proxy: %.0f ms\n",
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - restarted)
          .count());
  for (int k = 0; k < kSessions; ++k) {
    auto s = client_->GetSession(names[k]);
    ASSERT_TRUE(s.ok()) << names[k] << ": " << s.status().ToString();
    EXPECT_EQ(s->state(), v1::Session::FINISHED);
    auto t = client_->GetTrajectory(names[k]);
    ASSERT_TRUE(t.ok()) << t.status().ToString();
    EXPECT_EQ(t->SerializeAsString(), trajectories[names[k]]) << names[k];
  }
  // The replica that answers reconnects to its peer within a second.
  EXPECT_TRUE(Eventually([&] {
    unreachable.clear();
    listed = ListAll(*client_, 3, &unreachable);
    return unreachable.empty();
  })) << unreachable.front();
  EXPECT_EQ(listed.size(), kSessions + 1u);
}

}  // namespace
}  // namespace slapse
