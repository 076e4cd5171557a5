// SlapseServer: the gRPC server (slapse.v1.SlapseService, health checking,
// reflection) around a SessionManager.
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

#include <grpcpp/server.h>

#include "core/common/status.h"
#include "server/service.h"
#include "server/session_manager.h"

namespace slapse::server {

struct ServerOptions {
  // Address to listen on; "0.0.0.0" for every interface.
  std::string address = "127.0.0.1";
  // TCP port; 0 picks a free one (see SlapseServer::port()).
  int port = 50051;
  SessionManagerOptions sessions;
  // How long Shutdown() lets running rpcs finish before cancelling them.
  double shutdown_grace_s = 2.0;
};

class SlapseServer {
 public:
  // Binds and starts serving. UNAVAILABLE if the address cannot be bound.
  static StatusOr<std::unique_ptr<SlapseServer>> Start(const ServerOptions& options);
  // Shuts down if still running.
  ~SlapseServer();

  int port() const { return port_; }
  SessionManager& sessions() { return manager_; }

  // Graceful shutdown: stops accepting calls, stops every session (they end
  // STOPPED, watch streams end), waits up to shutdown_grace_s for rpcs in
  // flight, then joins the session workers. Idempotent.
  void Shutdown();
  // Blocks until Shutdown() has completed.
  void Wait();

 private:
  explicit SlapseServer(const ServerOptions& options);

  ServerOptions options_;
  SessionManager manager_;
  SlapseServiceImpl service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::mutex shutdown_mu_;
  bool shut_down_ = false;
};

}  // namespace slapse::server
