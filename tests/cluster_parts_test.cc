// The parts of the scale-out without a proxy: session names that carry
// their replica (api/session_name.h), the peer list, and ListSessions fanned
// out over real in-process servers on loopback (server/peers.h): the query's
// filter, order and pages over the union, a misrouted call's error, a peer
// that is down named in unreachable_peers, and the fan-out over mTLS with the
// caller's token forwarded (a certificate made by the openssl CLI).
#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "api/session_name.h"
#include "client/lib/client.h"
#include "server/server.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

TEST(SessionNameTest, CarriesTheReplica) {
  EXPECT_EQ(api::MakeSessionName("slapse-0", "abc234"), "sessions/slapse-0-abc234");
  EXPECT_EQ(api::MakeSessionName("", "abc234"), "sessions/abc234");
  EXPECT_EQ(api::SessionReplica("sessions/slapse-0-abc234"), "slapse-0");
  EXPECT_EQ(api::SessionReplica("sessions/r1-abc234"), "r1");
  EXPECT_EQ(api::SessionReplica("sessions/abc234"), "");     // a single server's name
  EXPECT_EQ(api::SessionReplica("sessions/-abc234"), "");    // no replica before the '-'
  EXPECT_EQ(api::SessionReplica("sessions/a--abc234"), "");  // "a-" is no replica id
  EXPECT_EQ(api::SessionReplica("other/r1-abc"), "");
  EXPECT_EQ(api::SessionReplica(""), "");
}

TEST(SessionNameTest, ReplicaIdIsADnsLabel) {
  EXPECT_TRUE(api::CheckReplicaId("slapse-0").ok());
  EXPECT_TRUE(api::CheckReplicaId("a").ok());
  EXPECT_TRUE(api::CheckReplicaId(std::string(32, 'a')).ok());
  for (const std::string bad : {"", "-a", "a-", "Slapse-0", "a.b", "a_b", "a b"}) {
    const Status s = api::CheckReplicaId(bad);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << "'" << bad << "'";
  }
  EXPECT_EQ(api::CheckReplicaId(std::string(33, 'a')).code(), StatusCode::kInvalidArgument);
}

TEST(PeerOptionsTest, ParsesAndChecksTheList) {
  EXPECT_EQ(server::SplitPeerList(" a:1, b:2 ,,c:3"),
            (std::vector<std::string>{"a:1", "b:2", "c:3"}));
  EXPECT_TRUE(server::SplitPeerList("").empty());
  server::PeerOptions o;
  o.addresses = {"slapse-0.slapse-pods:50051", "127.0.0.1:1"};
  EXPECT_TRUE(o.Check().ok());
  for (const std::string bad : {"host", "host:", ":50051", "host:50x"}) {
    o.addresses = {bad};
    EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument) << bad;
  }
  o.addresses = {};
  o.timeout_s = 0;
  EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument);
}

TEST(ClusterOptionsTest, PeersNeedAReplicaIdAndIdsAreChecked) {
  server::ServerOptions o;
  o.port = 0;
  o.peers = {"127.0.0.1:1"};
  auto no_id = server::SlapseServer::Start(o);
  ASSERT_FALSE(no_id.ok());
  EXPECT_EQ(no_id.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(no_id.status().message().find("--replica-id"), std::string::npos);
  o.sessions.replica_id = "Bad_Id";
  EXPECT_EQ(server::SlapseServer::Start(o).status().code(), StatusCode::kInvalidArgument);
}

// Three in-process replicas r0, r1, r2 on loopback, each with every replica
// (itself included) as a peer.
class FanoutTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // Ports first (distinct free ones), then the peers of each.
    for (int i = 0; i < 3; ++i) {
      ports_.push_back(testing::FreeLoopbackTcpPort());
      ASSERT_NE(ports_.back(), 0);
    }
    std::vector<std::string> peers;
    for (int port : ports_) peers.push_back("127.0.0.1:" + std::to_string(port));
    for (int i = 0; i < 3; ++i) {
      server::ServerOptions o;
      o.port = ports_[i];
      o.sessions.replica_id = "r" + std::to_string(i);
      o.peers = peers;
      o.peer_timeout_s = 5;
      auto s = server::SlapseServer::Start(o);
      ASSERT_TRUE(s.ok()) << s.status().ToString();
      servers_.push_back(std::move(*s));
      clients_.push_back(client::SlapseClient::Connect(peers[i]));
    }
  }

  v1::Session Request(const std::string& site) const {
    v1::Session s;
    s.mutable_intrinsics()->set_fx_px(500);
    s.mutable_intrinsics()->set_fy_px(500);
    s.mutable_intrinsics()->set_cx_px(320);
    s.mutable_intrinsics()->set_cy_px(240);
    s.mutable_upload();
    (*s.mutable_labels())["site"] = site;
    return s;
  }

  std::vector<int> ports_;
  std::vector<std::unique_ptr<server::SlapseServer>> servers_;
  std::vector<std::unique_ptr<client::SlapseClient>> clients_;
};

TEST_F(FanoutTest, ListsEveryReplicaWithTheQueryOverTheUnion) {
  // Two sessions per replica, created on it; site "a" on r0 and r2.
  std::vector<std::string> names;
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < 2; ++k) {
      auto s = clients_[i]->CreateSession(Request(i == 1 ? "b" : "a"));
      ASSERT_TRUE(s.ok()) << s.status().ToString();
      EXPECT_EQ(api::SessionReplica(s->name()), "r" + std::to_string(i));
      names.push_back(s->name());
    }
  }
  // Any replica lists all six, in creation order, each once (self skipped).
  for (int i = 0; i < 3; ++i) {
    auto all = clients_[i]->ListSessions(100, "", v1::Session::STATE_UNSPECIFIED);
    ASSERT_TRUE(all.ok()) << all.status().ToString();
    EXPECT_EQ(all->unreachable_peers_size(), 0);
    std::vector<std::string> got;
    for (const auto& s : all->sessions()) got.push_back(s.name());
    EXPECT_EQ(got, names) << "asked r" << i;
  }
  // Pages of 3 over the union, ordered by name descending, filtered by label.
  v1::ListSessionsRequest request;
  request.set_filter("labels.site=a");
  request.set_order_by("name desc");
  request.set_page_size(3);
  std::vector<std::string> paged;
  do {
    auto page = clients_[1]->ListSessions(request);
    ASSERT_TRUE(page.ok()) << page.status().ToString();
    EXPECT_LE(page->sessions_size(), 3);
    for (const auto& s : page->sessions()) paged.push_back(s.name());
    request.set_page_token(page->next_page_token());
  } while (!request.page_token().empty());
  std::vector<std::string> want = {names[0], names[1], names[4], names[5]};
  std::sort(want.rbegin(), want.rend());
  EXPECT_EQ(paged, want);
  // A bad query fails before any peer is asked, precisely.
  v1::ListSessionsRequest bad;
  bad.set_filter("nonsense=1");
  EXPECT_EQ(clients_[0]->ListSessions(bad).status().code(), StatusCode::kInvalidArgument);
  // A misrouted call says whose session it is.
  auto misrouted = clients_[0]->GetSession(names[2]);
  EXPECT_EQ(misrouted.status().code(), StatusCode::kNotFound);
  EXPECT_NE(misrouted.status().message().find("belongs to replica 'r1' and this is 'r0'"),
            std::string::npos)
      << misrouted.status().message();
}

TEST_F(FanoutTest, APeerDownIsNamedNotSilentlyMissing) {
  auto mine = clients_[0]->CreateSession(Request("a"));
  auto theirs = clients_[2]->CreateSession(Request("a"));
  ASSERT_TRUE(mine.ok() && theirs.ok());
  servers_[1]->Shutdown();
  auto all = clients_[0]->ListSessions(100, "", v1::Session::STATE_UNSPECIFIED);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  ASSERT_EQ(all->sessions_size(), 2);
  EXPECT_EQ(all->sessions(0).name(), mine->name());
  EXPECT_EQ(all->sessions(1).name(), theirs->name());
  ASSERT_EQ(all->unreachable_peers_size(), 1);
  EXPECT_EQ(all->unreachable_peers(0).rfind(
                "127.0.0.1:" + std::to_string(ports_[1]) + ": UNAVAILABLE", 0),
            0u)
      << all->unreachable_peers(0);
}

// Two replicas with TLS, client certificates (mTLS) and bearer tokens: the
// fan-out calls its peer over TLS with the server's own certificate and
// forwards the caller's token. One self-signed certificate (CA:TRUE, for
// 127.0.0.1, server and client use) is the servers', the client's and the CA.
TEST(FanoutTlsTest, AsksPeersOverMutualTlsWithTheCallersToken) {
  const std::string dir = testing::MakeTempDir("cluster_tls");
  const std::string key = dir + "/key.pem", cert = dir + "/cert.pem";
  ASSERT_EQ(testing::RunCommand(
                "openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes "
                "-keyout " +
                key + " -out " + cert +
                " -days 2 -subj /CN=localhost -addext subjectAltName=IP:127.0.0.1 "
                "-addext extendedKeyUsage=serverAuth,clientAuth >/dev/null 2>&1"),
            0);
  testing::WriteFileBytes(dir + "/tokens.json",
                          R"({"tokens": [{"token": "tls-token-0123456789", "tenant": "t"}]})");
  const std::vector<int> ports = {testing::FreeLoopbackTcpPort(), testing::FreeLoopbackTcpPort()};
  ASSERT_NE(ports[0], 0);
  ASSERT_NE(ports[1], 0);
  std::vector<std::unique_ptr<server::SlapseServer>> servers;
  std::vector<std::unique_ptr<client::SlapseClient>> clients;
  client::ClientOptions c;
  c.tls = true;
  c.tls_ca_file = cert;
  c.tls_cert_file = cert;
  c.tls_key_file = key;
  c.token = "tls-token-0123456789";
  for (int i = 0; i < 2; ++i) {
    server::ServerOptions o;
    o.port = ports[i];
    o.sessions.replica_id = "t" + std::to_string(i);
    o.peers = {"127.0.0.1:" + std::to_string(ports[0]), "127.0.0.1:" + std::to_string(ports[1])};
    o.auth.tls_cert_file = cert;
    o.auth.tls_key_file = key;
    o.auth.tls_client_ca_file = cert;
    o.auth.tokens_file = dir + "/tokens.json";
    o.peer_tls_ca_file = cert;
    auto s = server::SlapseServer::Start(o);
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    servers.push_back(std::move(*s));
    clients.push_back(client::SlapseClient::Connect(o.peers[i], c));
  }
  v1::Session request;
  request.mutable_intrinsics()->set_fx_px(500);
  request.mutable_intrinsics()->set_fy_px(500);
  request.mutable_intrinsics()->set_cx_px(320);
  request.mutable_intrinsics()->set_cy_px(240);
  request.mutable_upload();
  std::set<std::string> names;
  for (auto& client : clients) {
    auto s = client->CreateSession(request);
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    names.insert(s->name());
  }
  auto all = clients[0]->ListSessions(10, "", v1::Session::STATE_UNSPECIFIED);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  EXPECT_EQ(all->unreachable_peers_size(), 0)
      << (all->unreachable_peers_size() ? all->unreachable_peers(0) : "");
  std::set<std::string> listed;
  for (const auto& s : all->sessions()) listed.insert(s.name());
  EXPECT_EQ(listed, names);
}

}  // namespace
}  // namespace slapse
