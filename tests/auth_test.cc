// Auth end to end against real servers on loopback: TLS and mTLS with a CA
// and certificates the test makes with the openssl CLI, bearer tokens mapped
// to tenants (isolation, read-only role, reload of the tokens file), the
// loopback-only default bind, and secrets that never leave (a planted URL
// password, query token and bearer token grepped for in every output: rpc
// responses, watch events, error messages, the CLI's output and the server's
// stderr).
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <fcntl.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

#include "api/convert.h"
#include "client/lib/client.h"
#include "server/auth.h"
#include "server/server.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::ClientOptions;
using client::SlapseClient;

constexpr char kTokenA[] = "tenant-a-token-0123456789";
constexpr char kTokenB[] = "tenant-b-token-9876543210";
constexpr char kTokenRo[] = "read-only-token-abcdefghij";

// A CA, a server certificate for 127.0.0.1 / localhost and a client
// certificate it signed, and a second CA that signed nothing of ours.
struct Certs {
  std::string ca, server_cert, server_key, client_cert, client_key, other_ca, other_client_cert,
      other_client_key;
};

bool Openssl(const std::string& args) {
  return testing::RunCommand("openssl " + args + " >/dev/null 2>&1") == 0;
}

// A P-256 key and a certificate signed by `ca` (self-signed if empty).
bool MakeCert(const std::string& dir, const std::string& name, const std::string& cn,
              const std::string& ca, const std::string& ext) {
  const std::string key = dir + "/" + name + ".key", pem = dir + "/" + name + ".pem";
  const std::string newkey = "-newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout ";
  if (ca.empty()) {
    // The config's v3_ca extensions make it a CA (basicConstraints CA:TRUE).
    return Openssl("req -x509 " + newkey + key + " -out " + pem + " -days 2 -subj /CN=" + cn);
  }
  const std::string ext_file = dir + "/" + name + ".ext";
  testing::WriteFileBytes(ext_file, ext + "\n");
  return Openssl("req " + newkey + key + " -out " + dir + "/" + name + ".csr -subj /CN=" + cn) &&
         Openssl("x509 -req -in " + dir + "/" + name + ".csr -CA " + dir + "/" + ca +
                 ".pem -CAkey " + dir + "/" + ca + ".key -CAcreateserial -out " + pem +
                 " -days 2 -extfile " + ext_file);
}

Certs MakeCerts() {
  const std::string dir = testing::MakeTempDir("auth_certs");
  const bool ok =
      MakeCert(dir, "ca", "slapse-test-ca", "", "") &&
      MakeCert(dir, "server", "localhost", "ca",
               "subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth") &&
      MakeCert(dir, "client", "slapse-test-client", "ca", "extendedKeyUsage=clientAuth") &&
      MakeCert(dir, "other_ca", "other-ca", "", "") &&
      MakeCert(dir, "other_client", "other-client", "other_ca", "extendedKeyUsage=clientAuth");
  EXPECT_TRUE(ok) << "openssl failed in " << dir;
  return {dir + "/ca.pem",           dir + "/server.pem",      dir + "/server.key",
          dir + "/client.pem",       dir + "/client.key",      dir + "/other_ca.pem",
          dir + "/other_client.pem", dir + "/other_client.key"};
}

std::string TokensJson(const std::vector<std::vector<std::string>>& entries) {
  std::string out = "{\"tokens\": [";
  for (size_t i = 0; i < entries.size(); ++i) {
    const auto& e = entries[i];
    out += std::string(i ? ", " : "") + "{\"token\": \"" + e[0] + "\", \"tenant\": \"" + e[1] +
           "\"" + (e.size() > 2 ? ", \"role\": \"" + e[2] + "\"" : "") + "}";
  }
  return out + "]}\n";
}

// Replaces the file atomically (as an operator's editor or config tool would).
void ReplaceFile(const std::string& path, const std::string& text) {
  testing::WriteFileBytes(path + ".tmp", text);
  ASSERT_EQ(std::rename((path + ".tmp").c_str(), path.c_str()), 0);
}

std::unique_ptr<server::SlapseServer> StartServer(const server::AuthOptions& auth) {
  server::ServerOptions o;
  o.address = "127.0.0.1";
  o.port = 0;
  o.shutdown_grace_s = 1;
  o.auth = auth;
  auto s = server::SlapseServer::Start(o);
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return s.ok() ? std::move(*s) : nullptr;
}

std::unique_ptr<SlapseClient> ClientOf(const server::SlapseServer& s, ClientOptions o,
                                       const std::string& host = "127.0.0.1") {
  const ClientOptions t = testing::TestClientOptions();
  o.rpc_timeout_s = t.rpc_timeout_s;
  o.upload_timeout_s = t.upload_timeout_s;
  o.watch_timeout_s = t.watch_timeout_s;
  EXPECT_TRUE(o.Check().ok()) << o.Check().ToString();
  return SlapseClient::Connect(host + ":" + std::to_string(s.port()), o);
}

ClientOptions WithToken(const std::string& token) {
  ClientOptions o;
  o.token = token;
  return o;
}

v1::Session UploadRequest() {
  v1::Session s;
  s.mutable_upload();
  v1::Intrinsics* k = s.mutable_intrinsics();
  k->set_fx_px(300);
  k->set_fy_px(300);
  k->set_cx_px(160);
  k->set_cy_px(120);
  return s;
}

// --- TLS ----------------------------------------------------------------------

class TlsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { certs_ = new Certs(MakeCerts()); }
  static void TearDownTestSuite() { delete certs_; }
  static Certs* certs_;
};
Certs* TlsTest::certs_ = nullptr;

TEST_F(TlsTest, ConnectsWithTheRightCaAndNotOtherwise) {
  server::AuthOptions auth;
  auth.tls_cert_file = certs_->server_cert;
  auth.tls_key_file = certs_->server_key;
  auto server = StartServer(auth);
  ASSERT_NE(server, nullptr);

  ClientOptions good;
  good.tls = true;
  good.tls_ca_file = certs_->ca;
  auto ok = ClientOf(*server, good)->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  EXPECT_TRUE(ok.ok()) << ok.status().ToString();
  // The certificate names localhost too.
  auto by_name =
      ClientOf(*server, good, "localhost")->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  EXPECT_TRUE(by_name.ok()) << by_name.status().ToString();

  ClientOptions wrong_ca = good;
  wrong_ca.tls_ca_file = certs_->other_ca;
  auto refused = ClientOf(*server, wrong_ca)->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  EXPECT_EQ(refused.status().code(), StatusCode::kUnavailable) << refused.status().ToString();

  // Plain text to a TLS server gets nowhere either.
  auto plain = ClientOf(*server, {})->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  EXPECT_EQ(plain.status().code(), StatusCode::kUnavailable) << plain.status().ToString();
}

TEST_F(TlsTest, MutualTlsNeedsAClientCertificateFromTheClientCa) {
  server::AuthOptions auth;
  auth.tls_cert_file = certs_->server_cert;
  auth.tls_key_file = certs_->server_key;
  auth.tls_client_ca_file = certs_->ca;
  auto server = StartServer(auth);
  ASSERT_NE(server, nullptr);

  ClientOptions no_cert;
  no_cert.tls = true;
  no_cert.tls_ca_file = certs_->ca;
  auto refused = ClientOf(*server, no_cert)->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  EXPECT_EQ(refused.status().code(), StatusCode::kUnavailable) << refused.status().ToString();

  ClientOptions foreign = no_cert;
  foreign.tls_cert_file = certs_->other_client_cert;
  foreign.tls_key_file = certs_->other_client_key;
  auto refused2 = ClientOf(*server, foreign)->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  EXPECT_EQ(refused2.status().code(), StatusCode::kUnavailable) << refused2.status().ToString();

  ClientOptions with_cert = no_cert;
  with_cert.tls_cert_file = certs_->client_cert;
  with_cert.tls_key_file = certs_->client_key;
  auto ok = ClientOf(*server, with_cert)->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  EXPECT_TRUE(ok.ok()) << ok.status().ToString();
}

TEST(TlsOptionsTest, BadFilesAreRefusedWithTheirFlag) {
  server::AuthOptions auth;
  auth.tls_key_file = "/nonexistent/key.pem";
  server::ServerOptions o;
  o.port = 0;
  o.auth = auth;
  auto s = server::SlapseServer::Start(o);
  EXPECT_EQ(s.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("--tls-cert"), std::string::npos) << s.status().message();
  o.auth.tls_cert_file = "/nonexistent/cert.pem";
  s = server::SlapseServer::Start(o);
  EXPECT_EQ(s.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("'/nonexistent/cert.pem' cannot be read"), std::string::npos)
      << s.status().message();
  ClientOptions c;
  c.tls_ca_file = "/nonexistent/ca.pem";
  EXPECT_EQ(c.Check().code(), StatusCode::kInvalidArgument);  // without --tls
  c.tls = true;
  EXPECT_NE(c.Check().message().find("--ca '/nonexistent/ca.pem' cannot be read"),
            std::string::npos)
      << c.Check().message();
}

// --- tokens and tenants -----------------------------------------------------------

class TokenTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::MakeTempDir("auth_tokens");
    tokens_ = dir_ + "/tokens.json";
    testing::WriteFileBytes(
        tokens_,
        TokensJson({{kTokenA, "acme"}, {kTokenB, "globex"}, {kTokenRo, "acme", "read_only"}}));
    server::AuthOptions auth;
    auth.tokens_file = tokens_;
    auth.tokens_reload_interval_ms = 0;  // every rpc looks: the reload test needs no sleep
    server_ = StartServer(auth);
    ASSERT_NE(server_, nullptr);
    a_ = ClientOf(*server_, WithToken(kTokenA));
    b_ = ClientOf(*server_, WithToken(kTokenB));
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  std::string dir_, tokens_;
  std::unique_ptr<server::SlapseServer> server_;
  std::unique_ptr<SlapseClient> a_, b_;
};

TEST_F(TokenTest, NoTokenOrABadOneIsUnauthenticatedOnEveryRpc) {
  const std::string bad_token = "not-a-valid-token-but-long-enough";
  for (const ClientOptions& o : {ClientOptions{}, WithToken(bad_token)}) {
    auto c = ClientOf(*server_, o);
    std::vector<Status> got = {
        c->CreateSession(UploadRequest()).status(),
        c->GetSession("sessions/1").status(),
        c->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED).status(),
        c->StopSession("sessions/1").status(),
        c->DeleteSession("sessions/1"),
        c->GetTrajectory("sessions/1").status(),
        c->GetPlaneMap("sessions/1").status(),
        c->UploadBytes("sessions/1", "abc").status(),
        c->Watch("sessions/1", 0, [](const v1::SessionEvent&) { return true; })};
    for (const Status& s : got) {
      EXPECT_EQ(s.code(), server::kUnauthenticated) << s.ToString();
      EXPECT_EQ(s.message().find(bad_token), std::string::npos) << s.message();
    }
    const std::string want = o.token.empty() ? "requires a bearer token" : "is not valid";
    EXPECT_NE(got[0].message().find(want), std::string::npos) << got[0].message();
  }
  // Not 'Bearer ...' at all.
  auto stub = v1::SlapseService::NewStub(grpc::CreateChannel(
      "127.0.0.1:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials()));
  grpc::ClientContext ctx;
  ctx.AddMetadata("authorization", std::string("Basic ") + kTokenA);
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  v1::ListSessionsResponse r;
  const grpc::Status s = stub->ListSessions(&ctx, v1::ListSessionsRequest(), &r);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_NE(s.error_message().find("not 'Bearer <token>'"), std::string::npos);
  EXPECT_EQ(s.error_message().find(kTokenA), std::string::npos);
}

TEST_F(TokenTest, ATenantSeesOnlyItsOwnSessions) {
  auto mine = a_->CreateSession(UploadRequest());
  ASSERT_TRUE(mine.ok()) << mine.status().ToString();
  EXPECT_EQ(mine->tenant(), "acme");
  // A client cannot claim another tenant.
  v1::Session claim = UploadRequest();
  claim.set_tenant("acme");
  auto theirs = b_->CreateSession(claim);
  ASSERT_TRUE(theirs.ok()) << theirs.status().ToString();
  EXPECT_EQ(theirs->tenant(), "globex");

  const std::string name = mine->name();
  // B's view of A's session is word for word an unknown session's.
  const Status unknown = b_->GetSession("sessions/999999").status();
  auto same = [&](const Status& s, const std::string& rpc) {
    EXPECT_EQ(s.code(), StatusCode::kNotFound) << rpc << ": " << s.ToString();
    EXPECT_EQ(s.message(), "no session '" + name + "' on this server") << rpc;
  };
  same(b_->GetSession(name).status(), "Get");
  same(b_->StopSession(name).status(), "Stop");
  same(b_->DeleteSession(name), "Delete");
  same(b_->GetTrajectory(name).status(), "GetTrajectory");
  same(b_->GetPlaneMap(name).status(), "GetPlaneMap");
  same(b_->UploadBytes(name, "abc").status(), "Upload");
  same(b_->Watch(name, 0, [](const v1::SessionEvent&) { return true; }), "Watch");
  EXPECT_EQ(unknown.message(), "no session 'sessions/999999' on this server");

  auto listed_b = b_->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  ASSERT_TRUE(listed_b.ok());
  ASSERT_EQ(listed_b->sessions_size(), 1);
  EXPECT_EQ(listed_b->sessions(0).name(), theirs->name());
  auto listed_a = a_->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  ASSERT_TRUE(listed_a.ok());
  ASSERT_EQ(listed_a->sessions_size(), 1);
  EXPECT_EQ(listed_a->sessions(0).name(), name);
  // Pages hold only the tenant's sessions too.
  auto page = a_->ListSessions(1, "", v1::Session::STATE_UNSPECIFIED);
  ASSERT_TRUE(page.ok());
  EXPECT_EQ(page->sessions_size(), 1);
  EXPECT_TRUE(page->next_page_token().empty());

  // B's attempts changed nothing: A's session is still there, still CREATED.
  auto still = a_->GetSession(name);
  ASSERT_TRUE(still.ok()) << still.status().ToString();
  EXPECT_EQ(still->state(), v1::Session::CREATED);
  EXPECT_TRUE(a_->StopSession(name).ok());
  EXPECT_TRUE(a_->DeleteSession(name).ok());
  (void)b_->DeleteSession(theirs->name());
}

TEST_F(TokenTest, AReadOnlyTokenReadsButDoesNotChange) {
  auto mine = a_->CreateSession(UploadRequest());
  ASSERT_TRUE(mine.ok());
  auto ro = ClientOf(*server_, WithToken(kTokenRo));
  // Same tenant: it sees acme's session.
  auto got = ro->GetSession(mine->name());
  EXPECT_TRUE(got.ok()) << got.status().ToString();
  auto listed = ro->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED);
  ASSERT_TRUE(listed.ok());
  EXPECT_EQ(listed->sessions_size(), 1);
  for (const Status& s :
       {ro->CreateSession(UploadRequest()).status(), ro->StopSession(mine->name()).status(),
        ro->DeleteSession(mine->name()), ro->UploadBytes(mine->name(), "abc").status()}) {
    EXPECT_EQ(s.code(), StatusCode::kPermissionDenied) << s.ToString();
    EXPECT_NE(s.message().find("read-only token"), std::string::npos) << s.message();
  }
  EXPECT_EQ(a_->GetSession(mine->name())->state(), v1::Session::CREATED);
  (void)a_->StopSession(mine->name());
}

TEST_F(TokenTest, ReloadingTheTokensFileAddsAndRevokes) {
  const std::string kTokenC = "tenant-c-token-added-later";
  auto c = ClientOf(*server_, WithToken(kTokenC));
  EXPECT_EQ(c->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED).status().code(),
            server::kUnauthenticated);
  // C added, B revoked.
  ReplaceFile(tokens_, TokensJson({{kTokenA, "acme"}, {kTokenC, "initech"}}));
  EXPECT_TRUE(c->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED).ok());
  EXPECT_EQ(b_->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED).status().code(),
            server::kUnauthenticated);
  EXPECT_TRUE(a_->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED).ok());
  // A broken new version is refused: the old tokens stay in force.
  ReplaceFile(tokens_, "{\"tokens\": [{\"token\": \"short\", \"tenant\": \"x\"}]}");
  EXPECT_TRUE(c->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED).ok());
  EXPECT_EQ(server_->ReloadTokens().code(), StatusCode::kInvalidArgument);
  // Rewritten in place (same inode): noticed by its size / mtime.
  testing::WriteFileBytes(tokens_, TokensJson({{kTokenB, "globex"}}));
  EXPECT_TRUE(b_->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED).ok());
  EXPECT_EQ(c->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED).status().code(),
            server::kUnauthenticated);
}

TEST(TokensFileTest, MalformedFilesAreRefusedWithoutEchoingTokens) {
  const std::string dir = testing::MakeTempDir("auth_tokens_bad");
  const std::string path = dir + "/t.json";
  struct Case {
    std::string text, fragment;
  };
  const std::vector<Case> cases = {
      {"not json", "tokens file"},
      {"{}", "key 'tokens' (a list) is missing"},
      {"{\"tokens\": [{\"token\": \"shortsecret\", \"tenant\": \"a\"}]}", "at least 16 characters"},
      {"{\"tokens\": [{\"token\": \"long-enough-secret-1\", \"tenant\": \"a b\"}]}",
       "'tenant' must be"},
      {"{\"tokens\": [{\"token\": \"long-enough-secret-1\", \"tenant\": \"a\", \"role\": "
       "\"root\"}]}",
       "'role' must be"},
      {"{\"tokens\": [{\"token_sha256\": \"abc\", \"tenant\": \"a\"}]}", "64 hex digits"},
      {"{\"tokens\": [{\"token\": \"long-enough-secret-1\", \"tenant\": \"a\"}, {\"token\": "
       "\"long-enough-secret-1\", \"tenant\": \"b\"}]}",
       "tokens[1]: the same token as tokens[0]"},
  };
  for (const Case& c : cases) {
    testing::WriteFileBytes(path, c.text);
    server::AuthOptions o;
    o.tokens_file = path;
    auto auth = server::Authenticator::Create(o);
    ASSERT_FALSE(auth.ok()) << c.text;
    EXPECT_EQ(auth.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(auth.status().message().find(c.fragment), std::string::npos)
        << auth.status().message();
    EXPECT_EQ(auth.status().message().find("secret"), std::string::npos) << auth.status().message();
  }
  // A SHA-256 entry (as `sha256sum` prints it): the file need not hold the token.
  const std::string token = "hashed-token-0123456789";
  testing::RunCommand("printf %s " + token + " | sha256sum | cut -c1-64 > " + dir + "/hash");
  std::string hex = testing::ReadFileBytes(dir + "/hash");
  hex = hex.substr(0, 64);
  testing::WriteFileBytes(
      path, "{\"tokens\": [{\"token_sha256\": \"" + hex + "\", \"tenant\": \"hashed\"}]}");
  server::AuthOptions o;
  o.tokens_file = path;
  auto auth = server::Authenticator::Create(o);
  ASSERT_TRUE(auth.ok()) << auth.status().ToString();
  auto caller = (*auth)->AuthenticateToken(token);
  ASSERT_TRUE(caller.ok()) << caller.status().ToString();
  EXPECT_EQ(caller->tenant, "hashed");
  EXPECT_EQ((*auth)->AuthenticateToken(token + "x").status().code(), server::kUnauthenticated);
}

// --- safe default bind ----------------------------------------------------------

TEST(BindTest, WithoutAuthOnlyLoopbackUnlessInsecure) {
  server::ServerOptions o;
  o.port = 0;
  o.address = "0.0.0.0";
  auto refused = server::SlapseServer::Start(o);
  EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find("refusing to listen on 0.0.0.0 without TLS and bearer "
                                            "tokens"),
            std::string::npos)
      << refused.status().message();
  o.auth.tokens_file = "/unused";
  refused = server::SlapseServer::Start(o);
  EXPECT_EQ(refused.status().code(), StatusCode::kFailedPrecondition);  // tokens in clear text
  o.auth = {};
  o.auth.allow_insecure = true;
  auto insecure = server::SlapseServer::Start(o);
  EXPECT_TRUE(insecure.ok()) << insecure.status().ToString();
  EXPECT_TRUE(server::IsLoopbackAddress("127.0.0.1"));
  EXPECT_TRUE(server::IsLoopbackAddress("[::1]"));
  EXPECT_TRUE(server::IsLoopbackAddress("localhost"));
  EXPECT_FALSE(server::IsLoopbackAddress("0.0.0.0"));
  EXPECT_FALSE(server::IsLoopbackAddress("10.0.0.1"));
}

// `slapse serve` run by the test: stdout and stderr to files, killed with it.
class ServeProcess : public testing::ChildProcess {
 public:
  ServeProcess(const std::string& dir, std::vector<std::string> args)
      : out_(dir + "/serve.out"), err_(dir + "/serve.err") {
    // --http-port 0: no HTTP listener, so the fixed default 8080 cannot collide
    // with another test's server running at the same time.
    // --rtsp-port 0 likewise for the RTSP ingest port (8554).
    args.insert(args.begin(),
                {SLAPSE_CLI, "serve", "--port", "0", "--http-port", "0", "--rtsp-port", "0"});
    std::vector<char*> c;
    for (std::string& a : args) c.push_back(a.data());
    c.push_back(nullptr);
    pid_ = fork();
    if (pid_ == 0) {
      const int out = open(out_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      const int err = open(err_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      dup2(out, 1);
      dup2(err, 2);
      execv(SLAPSE_CLI, c.data());
      _exit(127);
    }
  }
  // "ADDR:PORT" from the "slapse serving on ADDR:PORT" line (polls 20 s), or "".
  std::string Address() const {
    for (int i = 0; i < 2000; ++i) {
      const std::string out = testing::ReadFileBytes(out_);
      const size_t at = out.find("serving on ");
      if (at != std::string::npos) {
        const size_t end = out.find(' ', at + 11);
        return out.substr(at + 11, end - at - 11);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return "";
  }
  void Stop() {
    if (pid_ > 0) kill(pid_, SIGTERM);
    Wait(std::chrono::seconds(10));
  }
  std::string Stdout() const { return testing::ReadFileBytes(out_); }
  std::string Stderr() const { return testing::ReadFileBytes(err_); }

 private:
  std::string out_, err_;
};

// Whether the TCP sockets in LISTEN on `port` are bound to 127.0.0.1 only
// (none to another or every interface), from /proc/net/tcp and tcp6.
bool ListensOnLoopbackOnly(int port) {
  char suffix[8];
  std::snprintf(suffix, sizeof(suffix), ":%04X", port);
  bool loopback = false, other = false;
  for (const std::string file : {"/proc/net/tcp", "/proc/net/tcp6"}) {
    std::ifstream in(file);
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      std::string slot, local, remote, state;
      fields >> slot >> local >> remote >> state;
      if (state != "0A" || local.size() < 5 || local.substr(local.size() - 5) != suffix) continue;
      // 127.0.0.1, or the same as a v4-mapped IPv6 address (::ffff:127.0.0.1)
      // of a dual-stack socket, as gRPC binds it.
      const bool is_loopback = local == std::string("0100007F") + suffix ||
                               local == std::string("0000000000000000FFFF00000100007F") + suffix;
      (is_loopback ? loopback : other) = true;
    }
  }
  return loopback && !other;
}

TEST(BindTest, TheCliServesLoopbackByDefaultAndRefusesAnUnprotectedPublicAddress) {
  const std::string dir = testing::MakeTempDir("auth_bind");
  {
    ServeProcess serve(dir, {"--data-dir", dir + "/data"});  // not the shared default
    const std::string address = serve.Address();
    ASSERT_EQ(address.rfind("127.0.0.1:", 0), 0u) << serve.Stdout() << serve.Stderr();
    const int port = std::stoi(address.substr(10));
    EXPECT_TRUE(ListensOnLoopbackOnly(port));
    // The RTSP ingest port follows --address.
    const std::string out = serve.Stdout();
    const std::string rtsp = "RTSP ingest on rtsp://127.0.0.1:";
    ASSERT_NE(out.find(rtsp), std::string::npos) << out;
    EXPECT_TRUE(ListensOnLoopbackOnly(std::stoi(out.substr(out.find(rtsp) + rtsp.size()))));
    serve.Stop();
  }
  ServeProcess refused(dir, {"--address", "0.0.0.0"});
  EXPECT_EQ(refused.Wait(std::chrono::seconds(20)), 1);
  EXPECT_NE(refused.Stderr().find("refusing to listen on 0.0.0.0"), std::string::npos)
      << refused.Stderr();
}

// A bad --rtp-ports is a usage error naming the flag and the rule broken.
TEST(BindTest, TheCliRefusesABadRtpPortRangeNamingTheRule) {
  const std::string dir = testing::MakeTempDir("auth_rtp_ports");
  ServeProcess refused(dir, {"--data-dir", dir + "/data", "--rtp-ports", "40001-40099"});
  EXPECT_EQ(refused.Wait(std::chrono::seconds(20)), 2);
  EXPECT_NE(refused.Stderr().find("--rtp-ports"), std::string::npos) << refused.Stderr();
  EXPECT_NE(refused.Stderr().find("MIN must be even"), std::string::npos) << refused.Stderr();
}

// --- secrets never leave ------------------------------------------------------------

std::string Text(const google::protobuf::Message& m) { return m.DebugString(); }

TEST(SecretsTest, APlantedSecretAppearsInNoOutput) {
  const std::string kPassword = "PlantedPw4711", kQueryToken = "PlantedQueryTok4711";
  const std::string kBearer = "planted-bearer-token-4711";
  const std::string kWrongBearer = "planted-wrong-bearer-4711";
  const std::string dir = testing::MakeTempDir("auth_secrets");
  testing::WriteFileBytes(dir + "/tokens.json", TokensJson({{kBearer, "acme"}}));
  // A data directory of its own: the default one is locked by whichever test's
  // server started first when ctest runs them side by side.
  ServeProcess serve(dir, {"--tokens-file", dir + "/tokens.json", "--data-dir", dir + "/data"});
  const std::string address = serve.Address();
  ASSERT_FALSE(address.empty()) << serve.Stderr();

  ClientOptions o = testing::TestClientOptions();
  o.token = kBearer;
  auto c = SlapseClient::Connect(address, o);
  std::string outputs;  // everything that left the server or the CLI
  const std::string url = "rtsp://admin:" + kPassword +
                          "@127.0.0.1:" + std::to_string(testing::FreeLoopbackTcpPort()) +
                          "/cam?token=" + kQueryToken + "&ch=1";
  v1::Session r = UploadRequest();
  r.clear_upload();
  r.mutable_rtsp_pull()->set_url(url);
  r.mutable_rtsp_pull()->mutable_reconnect()->set_max_attempts(1);
  r.mutable_rtsp_pull()->mutable_reconnect()->set_initial_interval_ms(50);
  auto created = c->CreateSession(r);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  outputs += Text(*created);
  // Masked, not dropped: the operator still sees which camera.
  EXPECT_NE(created->rtsp_pull().url().find("rtsp://***@127.0.0.1:"), std::string::npos)
      << created->rtsp_pull().url();
  EXPECT_NE(created->rtsp_pull().url().find("?token=***&ch=1"), std::string::npos);
  const std::string name = created->name();
  Status watched = c->Watch(name, 0, [&](const v1::SessionEvent& e) {
    outputs += Text(e);
    return true;
  });
  EXPECT_TRUE(watched.ok()) << watched.ToString();
  auto got = c->GetSession(name);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->state(), v1::Session::FAILED);  // nobody at that port
  outputs += Text(*got);
  outputs += Text(*c->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED));
  outputs += Text(*c->StopSession(name));
  outputs += Text(*c->GetTrajectory(name));
  outputs += Text(*c->GetPlaneMap(name));
  // Errors: a malformed URL with the secrets in it, a wrong bearer token.
  v1::Session bad = r;
  bad.mutable_rtsp_pull()->set_url("rtsp://admin:" + kPassword + "@bad host/?token=" + kQueryToken);
  const Status refused = c->CreateSession(bad).status();
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  outputs += refused.ToString();
  ClientOptions wrong = o;
  wrong.token = kWrongBearer;
  outputs += SlapseClient::Connect(address, wrong)->GetSession(name).status().ToString();
  // The CLI, token from the environment.
  const std::string cli = "SLAPSE_TOKEN=" + kBearer + " " + SLAPSE_CLI;
  const std::string cli_out = dir + "/cli.out";
  for (const std::string& args :
       {"get " + name + " --json", std::string("list"), "watch " + name,
        "watch " + name + " --json",
        "create --rtsp-pull '" + url + "' --intrinsics 300,300,160,120 --reconnect-attempts 1",
        "create --rtsp-pull 'rtsp://admin:" + kPassword + "@bad host/?token=" + kQueryToken +
            "' --intrinsics 300,300,160,120",
        "export " + name + " --format json --out -"}) {
    testing::RunCommand(cli + " " + args + " --server " + address + " >>" + cli_out + " 2>&1");
  }
  testing::RunCommand(std::string(SLAPSE_CLI) + " get " + name + " --token " + kWrongBearer +
                      " --server " + address + " >>" + cli_out + " 2>&1");
  const std::string cli_text = testing::ReadFileBytes(cli_out);
  EXPECT_NE(cli_text.find("rtsp://***@"), std::string::npos) << cli_text;
  outputs += cli_text;
  serve.Stop();
  outputs += serve.Stdout() + serve.Stderr();

  for (const std::string& secret : {kPassword, kQueryToken, kBearer, kWrongBearer}) {
    EXPECT_EQ(outputs.find(secret), std::string::npos)
        << "'" << secret << "' leaked:\n"
        << outputs.substr(outputs.find(secret) > 400 ? outputs.find(secret) - 400 : 0, 800);
  }
}

// RTSP push: the publish password is shown once, in the CreateSession
// response (and `create`'s output); a wrong one planted by a publisher and
// the real one appear in no other output: rpcs, events, errors, the CLI, the
// server's log (which sees the refused and the accepted publisher).
TEST(SecretsTest, TheRtspPublishPasswordIsShownOnceOnly) {
  const std::string kWrongPassword = "PlantedPublishPw4711";
  const std::string dir = testing::MakeTempDir("auth_rtsp_secret");
  auto drive = testing::SimulateTestDrive("auth_rtsp", testing::SmallMpeg2DriveOptions(7, 2.0));
  ASSERT_TRUE(drive.ok()) << drive.status().ToString();
  ServeProcess serve(dir, {"--data-dir", dir + "/data"});
  const std::string address = serve.Address();
  ASSERT_FALSE(address.empty()) << serve.Stderr();
  auto c = SlapseClient::Connect(address, testing::TestClientOptions());
  v1::Session r = UploadRequest();
  r.clear_upload();
  *r.mutable_intrinsics() = api::IntrinsicsToProto(drive->intrinsics);
  r.mutable_rtsp_push()->set_path("cam");
  r.mutable_rtsp_push()->set_start_timeout_ms(20000);
  auto created = c->CreateSession(r);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string password = created->publish_credentials().password();
  ASSERT_GE(password.size(), 32u);
  const std::string name = created->name();
  std::string outputs;  // everything else that left the server or the CLI
  // A publisher with a wrong password is refused; the right one publishes.
  v1::Session wrong = *created;
  wrong.mutable_publish_credentials()->set_password(kWrongPassword);
  testing::FfmpegProcess refused({"-re", "-i", drive->video_path, "-c", "copy", "-f", "rtsp",
                                  "-rtsp_transport", "tcp", testing::PublishUrl(wrong)});
  EXPECT_NE(refused.Wait(std::chrono::seconds(10)), 0);
  testing::FfmpegProcess camera({"-re", "-i", drive->video_path, "-c", "copy", "-f", "rtsp",
                                 "-rtsp_transport", "tcp", testing::PublishUrl(*created)});
  Status watched = c->Watch(name, 0, [&](const v1::SessionEvent& e) {
    outputs += Text(e);
    return true;
  });
  EXPECT_TRUE(watched.ok()) << watched.ToString();
  auto got = c->GetSession(name);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->state(), v1::Session::FINISHED) << got->state_message();
  outputs += Text(*got);
  outputs += Text(*c->ListSessions(0, "", v1::Session::STATE_UNSPECIFIED));
  const std::string cli_out = dir + "/cli.out";
  for (const std::string& args :
       {"get " + name + " --json", std::string("list"), "watch " + name + " --json",
        "export " + name + " --format json --out -"}) {
    testing::RunCommand(std::string(SLAPSE_CLI) + " " + args + " --server " + address + " >>" +
                        cli_out + " 2>&1");
  }
  outputs += testing::ReadFileBytes(cli_out);
  // `create` shows the publish URL with the credentials, once.
  const std::string create_out = dir + "/create.out";
  testing::RunCommand(std::string(SLAPSE_CLI) + " create --rtsp-push cam2 --intrinsics " +
                      "300,300,160,120 --server " + address + " >" + create_out + " 2>&1");
  const std::string created_text = testing::ReadFileBytes(create_out);
  EXPECT_NE(created_text.find("rtsp://"), std::string::npos) << created_text;
  // Shown, not masked: rtsp://USER:PASSWORD@127.0.0.1:PORT/sessions/ID/cam2.
  EXPECT_NE(created_text.find("@127.0.0.1:"), std::string::npos) << created_text;
  EXPECT_EQ(created_text.find("***"), std::string::npos) << created_text;
  serve.Stop();
  outputs += serve.Stdout() + serve.Stderr();
  for (const std::string& secret : {password, kWrongPassword}) {
    EXPECT_EQ(outputs.find(secret), std::string::npos)
        << "'" << secret << "' leaked:\n"
        << outputs.substr(outputs.find(secret) > 400 ? outputs.find(secret) - 400 : 0, 800);
  }
}

}  // namespace
}  // namespace slapse
