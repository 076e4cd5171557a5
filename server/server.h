// SlapseServer: the gRPC server (slapse.v1.SlapseService, health checking,
// reflection) around a SessionManager, and its HTTP side (/metrics, the
// dashboard: server/dashboard.h).
//
// Health (grpc.health.v1.Health) answers per service name: "" (the server)
// and "slapse.v1.SlapseService" are SERVING from Start() until Shutdown().
//
//   ServerOptions o;
//   o.port = 0;  // ephemeral
//   auto server = SlapseServer::Start(o);
//   ... (*server)->port() ...
//   (*server)->Shutdown();
//
// Thread-safety: Shutdown() and Wait() may be called from any thread.
#pragma once

#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <grpcpp/server.h>

#include "core/common/status.h"
#include "server/auth.h"
#include "server/http_server.h"
#include "server/metrics.h"
#include "server/peers.h"
#include "server/service.h"
#include "server/session_manager.h"

namespace slapse::server {

struct ServerOptions {
  // Address to listen on; "0.0.0.0" for every interface. A non-loopback
  // address needs TLS and tokens in `auth`, or auth.allow_insecure
  // (CheckListenAddress): else Start fails with FAILED_PRECONDITION.
  std::string address = "127.0.0.1";
  // TCP port; 0 picks a free one (see SlapseServer::port()).
  int port = 50051;
  SessionManagerOptions sessions;
  // How long Shutdown() lets running rpcs finish before cancelling them.
  double shutdown_grace_s = 2.0;
  // TLS, bearer tokens and the insecure-bind override (server/auth.h).
  AuthOptions auth;
  // gRPC server reflection (grpc.reflection.v1alpha), for tools like grpcurl.
  bool reflection = true;
  // HTTP port for /metrics (Prometheus text format) and /healthz, on
  // `address`: 0 = no HTTP server, kAnyFreePort = a free one (see http_port()).
  // `slapse serve` uses 8080.
  static constexpr int kAnyFreePort = -1;
  int http_port = 0;
  // Scale-out (docs/DEPLOY.md): the other replicas ("host:port"; this one
  // may be listed too), which ListSessions asks as well (server/peers.h).
  // Needs sessions.replica_id. With TLS (auth.tls()), the peers are called
  // over TLS: peer_tls_ca_file signed their certificates ("" = the system's
  // roots) and this server's certificate is its client certificate.
  std::vector<std::string> peers;
  std::string peer_tls_ca_file;
  double peer_timeout_s = 3.0;
  // glibc malloc arenas of the whole process (mallopt M_ARENA_MAX, set by
  // Start): glibc's default, 8 per core, gives a session's threads (reader,
  // record pipeline, gRPC) arenas of their own, each keeping its freed
  // memory; 2 took ~1 MiB per live session off the RSS at 4 sessions with no
  // fps lost (docs/BENCHMARKS.md, issue 17). 0 = glibc's default.
  int malloc_arena_max = 2;
};

class SlapseServer {
 public:
  // Binds and starts serving. UNAVAILABLE if the address cannot be bound;
  // INVALID_ARGUMENT for unreadable TLS files or a bad tokens file;
  // FAILED_PRECONDITION for an unprotected non-loopback address.
  static StatusOr<std::unique_ptr<SlapseServer>> Start(const ServerOptions& options);
  // Shuts down if still running.
  ~SlapseServer();

  int port() const { return port_; }
  // The HTTP port, 0 if there is no HTTP server.
  int http_port() const { return http_ == nullptr ? 0 : http_->port(); }
  // What /metrics serves.
  std::string MetricsText() const { return metrics_->Exposition(); }
  SessionManager& sessions() { return manager_; }

  // Graceful shutdown: stops accepting calls, stops every session (they end
  // STOPPED, watch streams end), waits up to shutdown_grace_s for rpcs in
  // flight, then joins the session workers. Idempotent.
  void Shutdown();
  // Blocks until Shutdown() has completed.
  void Wait();
  // Re-reads the tokens file now (SIGHUP); on error the old tokens stay.
  Status ReloadTokens() { return auth_->Reload(); }

 private:
  SlapseServer(const ServerOptions& options, std::unique_ptr<Authenticator> auth);
  // Serves /metrics and /healthz when options_.http_port asks for it.
  Status StartHttp();

  ServerOptions options_;
  std::unique_ptr<Authenticator> auth_;
  SessionManager manager_;
  std::unique_ptr<PeerFanout> peers_;  // null without options.peers; before service_
  SlapseServiceImpl service_;
  std::unique_ptr<ServerMetrics> metrics_;  // before server_: its interceptors use it
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::unique_ptr<HttpServer> http_;
  std::mutex shutdown_mu_;
  bool shut_down_ = false;
};

}  // namespace slapse::server
