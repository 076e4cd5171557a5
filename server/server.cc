#include "server/server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server_builder.h>

#include <malloc.h>

#include <algorithm>
#include "api/session_name.h"
#include "server/dashboard.h"

namespace slapse::server {
namespace {

// Reflection on or off for one builder. Loading grpc++_reflection registers
// its plugin for every builder of the process (a static initializer), so the
// option first removes it, then adds one back if `enabled`.
class ReflectionOption : public grpc::ServerBuilderOption {
 public:
  explicit ReflectionOption(bool enabled) : enabled_(enabled) {}
  void UpdateArguments(grpc::ChannelArguments*) override {}
  void UpdatePlugins(std::vector<std::unique_ptr<grpc::ServerBuilderPlugin>>* plugins) override {
    auto reflection = std::make_unique<grpc::reflection::ProtoServerReflectionPlugin>();
    const std::string name = reflection->name();
    plugins->erase(std::remove_if(plugins->begin(), plugins->end(),
                                  [&](const auto& p) { return p->name() == name; }),
                   plugins->end());
    if (enabled_) plugins->push_back(std::move(reflection));
  }

 private:
  bool enabled_;
};

}  // namespace

SlapseServer::SlapseServer(const ServerOptions& options, std::unique_ptr<Authenticator> auth)
    : options_(options),
      auth_(std::move(auth)),
      manager_(options.sessions),
      service_(&manager_, auth_.get()),
      metrics_(std::make_unique<ServerMetrics>(&manager_)) {
  if (!options.peers.empty()) {
    PeerOptions p;
    p.addresses = options.peers;
    p.self_replica = options.sessions.replica_id;
    p.timeout_s = options.peer_timeout_s;
    p.tls = options.auth.tls();
    p.tls_ca_file = options.peer_tls_ca_file;
    p.tls_cert_file = options.auth.tls_cert_file;
    p.tls_key_file = options.auth.tls_key_file;
    peers_ = std::make_unique<PeerFanout>(std::move(p));
  }
  service_.SetCluster(options.sessions.replica_id, peers_.get());
}

// The cluster options: a well-formed replica id, and peers only with one.
static Status CheckClusterOptions(const ServerOptions& options) {
  if (!options.sessions.replica_id.empty()) {
    SLAPSE_RETURN_IF_ERROR(api::CheckReplicaId(options.sessions.replica_id));
  }
  if (options.peers.empty()) return Status::Ok();
  if (options.sessions.replica_id.empty()) {
    return InvalidArgumentError(
        "peers need a replica id (serve --replica-id), so that session "
        "names carry their owner");
  }
  PeerOptions p;
  p.addresses = options.peers;
  p.timeout_s = options.peer_timeout_s;
  return p.Check();
}

Status SlapseServer::StartHttp() {
  if (options_.http_port == 0) return Status::Ok();
  // The HTTP port speaks TLS when the gRPC port does (same files).
  http_ = std::make_unique<HttpServer>(HttpTls{
      options_.auth.tls_cert_file, options_.auth.tls_key_file, options_.auth.tls_client_ca_file});
  http_->Get("/metrics", [this](const HttpRequest&) {
    return HttpResponse{200, kPrometheusContentType, metrics_->Exposition()};
  });
  http_->Get("/healthz", [](const HttpRequest&) {
    return HttpResponse{200, "text/plain", "ok\n"};
  });
  MountDashboard(http_.get(), &manager_, auth_.get());
  return http_->Start(options_.address,
                      options_.http_port == ServerOptions::kAnyFreePort ? 0 : options_.http_port);
}

StatusOr<std::unique_ptr<SlapseServer>> SlapseServer::Start(const ServerOptions& options) {
  if (options.port < 0 || options.port > 65535) {
    return InvalidArgumentError("port must be in [0, 65535], got " + std::to_string(options.port));
  }
  if (options.sessions.max_sessions < 1) {
    return InvalidArgumentError("max_sessions must be >= 1");
  }
  if (options.sessions.retention_ttl_s < 0) {
    return InvalidArgumentError("retention_ttl_s must be >= 0 (0: keep results)");
  }
  if (options.sessions.retention_max_store_bytes < 0) {
    return InvalidArgumentError("retention_max_store_bytes must be >= 0 (0: no budget)");
  }
  if (options.malloc_arena_max < 0) {
    return InvalidArgumentError("malloc_arena_max must be >= 0 (0: glibc's default)");
  }
  if (options.malloc_arena_max > 0) mallopt(M_ARENA_MAX, options.malloc_arena_max);
  if (options.http_port < ServerOptions::kAnyFreePort || options.http_port > 65535) {
    return InvalidArgumentError("http_port must be in [0, 65535] (or kAnyFreePort), got " +
                                std::to_string(options.http_port));
  }
  SLAPSE_RETURN_IF_ERROR(CheckClusterOptions(options));
  SLAPSE_RETURN_IF_ERROR(CheckListenAddress(options.address, options.auth));
  auto credentials = MakeServerCredentials(options.auth);
  if (!credentials.ok()) return credentials.status();
  auto auth = Authenticator::Create(options.auth);
  if (!auth.ok()) return auth.status();
  grpc::EnableDefaultHealthCheckService(true);
  std::unique_ptr<SlapseServer> server(new SlapseServer(options, std::move(*auth)));
  // Restores the stored sessions before anyone can call.
  SLAPSE_RETURN_IF_ERROR(server->manager_.Open());
  grpc::ServerBuilder builder;
  const std::string address = options.address + ":" + std::to_string(options.port);
  builder.AddListeningPort(address, *credentials, &server->port_);
  // gRPC sets SO_REUSEPORT by default on Linux, which lets a second server
  // bind a port in use and silently take half its connections (a replica
  // started twice, or on a peer's port): address reuse only (restarts), as
  // the HTTP server (http_server.cc).
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.RegisterService(&server->service_);
  builder.SetMaxReceiveMessageSize(16 << 20);
  builder.SetOption(std::make_unique<ReflectionOption>(options.reflection));
  builder.experimental().SetInterceptorCreators(server->metrics_->InterceptorFactories());
  server->server_ = builder.BuildAndStart();
  if (server->server_ == nullptr || server->port_ == 0) {
    return UnavailableError("cannot listen on " + address + " (in use, or not a local address?)");
  }
  if (auto* health = server->server_->GetHealthCheckService()) {
    health->SetServingStatus(v1::SlapseService::service_full_name(), true);
  }
  if (Status http = server->StartHttp(); !http.ok()) return http;  // ~SlapseServer shuts down
  return server;
}

SlapseServer::~SlapseServer() { Shutdown(); }

void SlapseServer::Shutdown() {
  std::lock_guard<std::mutex> lock(shutdown_mu_);
  if (shut_down_) return;
  shut_down_ = true;
  if (http_ != nullptr) http_->Stop();
  if (server_ == nullptr) return;
  if (auto* health = server_->GetHealthCheckService()) health->Shutdown();
  // Sessions first: that ends watch streams and blocked uploads, so the
  // grace period below is rarely needed.
  service_.BeginShutdown();
  manager_.Shutdown();
  const auto grace = std::chrono::duration_cast<std::chrono::system_clock::duration>(
      std::chrono::duration<double>(options_.shutdown_grace_s));
  server_->Shutdown(std::chrono::system_clock::now() + grace);
  server_->Wait();
}

void SlapseServer::Wait() {
  if (server_ != nullptr) server_->Wait();
}

}  // namespace slapse::server
