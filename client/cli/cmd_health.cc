// `slapse health`: asks a server's gRPC health service (grpc.health.v1.Health)
// whether a service is SERVING; the container's HEALTHCHECK runs it.
// Exit 0: SERVING; 1: NOT_SERVING, unknown service or no answer (the reason
// on stderr); 2: usage.
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

#include <chrono>
#include <cstdio>

#include "client/cli/commands.h"
#include "client/cli/flags.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace slapse::cli {

int RunHealth(int argc, char** argv) {
  CommandLine cl("health", "[options]   (exit 0 if the service is SERVING, else 1)");
  CLI::App& app = cl.app();
  std::string server, service;
  double timeout_s = 3.0;
  AddServerFlag(&cl, &server);
  app.add_option("--service", service,
                 "the service asked about, e.g. slapse.v1.SlapseService (\"\": the server)")
      ->type_name("NAME")
      ->capture_default_str();
  app.add_option("--timeout-s", timeout_s, "give up after this long")
      ->type_name("S")
      ->capture_default_str();
  if (int rc = cl.Parse(argc, argv); rc >= 0) return rc;
  if (!cl.positional().empty()) return Fail("health", "expected no arguments (see --help)", 2);
  if (Status s = CheckRange("timeout-s", timeout_s, 0.001, 3600.0); !s.ok()) {
    return Fail("health", s.message(), 2);
  }
  auto stub = grpc::health::v1::Health::NewStub(
      grpc::CreateChannel(server, grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::microseconds(static_cast<int64_t>(timeout_s * 1e6)));
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(service);
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status status = stub->Check(&context, request, &response);
  const std::string what = service.empty() ? "the server" : service;
  if (!status.ok()) {
    return Fail("health", server + ": " + what + ": " +
                              (status.error_code() == grpc::StatusCode::NOT_FOUND
                                   ? "unknown service"
                                   : "no answer (" + status.error_message() + ")"));
  }
  const std::string state =
      grpc::health::v1::HealthCheckResponse::ServingStatus_Name(response.status());
  if (response.status() != grpc::health::v1::HealthCheckResponse::SERVING) {
    return Fail("health", server + ": " + what + " is " + state);
  }
  std::printf("%s: %s is %s\n", server.c_str(), what.c_str(), state.c_str());
  return 0;
}

}  // namespace slapse::cli
