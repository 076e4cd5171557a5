// HttpServer: the server's HTTP side (cpp-httplib): GET routes added by
// path, served from a thread of its own. The slapse server mounts /metrics
// (and /healthz) on it; more routes (a dashboard) are added the same way.
//
//   HttpServer http;
//   http.Get("/metrics", [&](const HttpRequest&) { return HttpResponse{200, type, text}; });
//   Status s = http.Start("0.0.0.0", 8080);   // port 0: a free one, see port()
//   ...
//   http.Stop();
//
// Unknown paths get 404, other methods 405 (httplib's defaults).
// Thread-safety: Get() before Start(); handlers run on httplib's thread pool,
// concurrently; Stop() from any thread.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <thread>

#include "core/common/status.h"

namespace httplib {
class Server;
}

namespace slapse::server {

struct HttpRequest {
  std::string path;
  std::multimap<std::string, std::string> params;  // the query string, decoded
};

struct HttpResponse {
  int status = 200;
  std::string content_type = "text/plain; charset=utf-8";
  std::string body;
};

using HttpHandler = std::function<HttpResponse(const HttpRequest&)>;

class HttpServer {
 public:
  HttpServer();
  // Stops if still serving.
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Serves GET (and HEAD) `path`, an exact path such as "/metrics".
  void Get(const std::string& path, HttpHandler handler);

  // Binds address:port (0: a free port) and serves on a thread of its own.
  // UNAVAILABLE if the address cannot be bound.
  Status Start(const std::string& address, int port);
  int port() const { return port_; }

  // Stops serving and joins the thread. Idempotent.
  void Stop();

 private:
  std::unique_ptr<httplib::Server> server_;
  std::thread thread_;
  int port_ = 0;
};

}  // namespace slapse::server
