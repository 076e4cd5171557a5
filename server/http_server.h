// HttpServer: the server's HTTP side (cpp-httplib): GET and POST routes
// added by exact path, served from a thread of its own. The slapse server
// mounts /metrics (and /healthz) on it, and the dashboard (server/dashboard.h)
// its pages and /api routes the same way. A response may be a stream
// (HttpResponse::stream: sent chunked as it is produced, e.g. server-sent
// events) instead of a body.
//
//   HttpServer http;
//   http.Get("/metrics", [&](const HttpRequest&) { return HttpResponse{200, type, text}; });
//   Status s = http.Start("0.0.0.0", 8080);   // port 0: a free one, see port()
//   ...
//   http.Stop();
//
// With HttpTls files it speaks HTTPS only (httplib's SSLServer, OpenSSL): the
// slapse server gives it the gRPC port's certificate, key and client CA.
//
// Unknown paths get 404, other methods 405 (httplib's defaults). Handlers
// run on a pool of kHttpThreads threads; a streamed response holds one for
// as long as it streams.
// Thread-safety: Get() / Post() before Start(); handlers run on httplib's thread pool,
// concurrently; Stop() from any thread.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/common/status.h"

namespace httplib {
class Server;
}

namespace slapse::server {

struct HttpRequest {
  std::string method;  // "GET", "HEAD" or "POST"
  std::string path;
  std::multimap<std::string, std::string> params;   // the query string (and a
                                                    // POSTed form), decoded
  std::multimap<std::string, std::string> headers;  // names as sent (httplib
                                                    // compares them case-insensitively)
  std::string body;

  // The first value of header `name` (case-insensitive), or "".
  std::string Header(const std::string& name) const;
  // The first value of query parameter `name`, or "".
  std::string Param(const std::string& name) const;
};

// Writes one chunk of a streamed response; false once the client has gone.
using HttpWrite = std::function<bool(const std::string& chunk)>;

struct HttpResponse {
  HttpResponse() = default;
  HttpResponse(int status, std::string content_type, std::string body)
      : status(status), content_type(std::move(content_type)), body(std::move(body)) {}

  int status = 200;
  std::string content_type = "text/plain; charset=utf-8";
  std::string body;
  // Extra headers (Set-Cookie, Content-Disposition, Cache-Control, ...).
  std::vector<std::pair<std::string, std::string>> headers;
  // When set, the body is ignored and the response is streamed: `stream` is
  // called again and again on the handler's thread, writes what it has with
  // `write` and returns false when the stream is complete (or the client
  // went away). It should not block for long (the server's Stop waits for it).
  std::function<bool(const HttpWrite& write)> stream;
};

using HttpHandler = std::function<HttpResponse(const HttpRequest&)>;

constexpr int kHttpThreads = 32;

// PEM files (as AuthOptions' for the gRPC port); no certificate: plain HTTP.
struct HttpTls {
  std::string cert_file, key_file;
  std::string client_ca_file;  // set: clients must present a certificate it signed
  bool on() const { return !cert_file.empty(); }
};

class HttpServer {
 public:
  explicit HttpServer(const HttpTls& tls = {});
  // Stops if still serving.
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Serves GET (and HEAD) `path`, an exact path such as "/metrics".
  void Get(const std::string& path, HttpHandler handler);
  // Serves POST `path` (an exact path).
  void Post(const std::string& path, HttpHandler handler);

  // Binds address:port (0: a free port) and serves on a thread of its own.
  // UNAVAILABLE if the address cannot be bound.
  Status Start(const std::string& address, int port);
  int port() const { return port_; }
  // Whether it speaks HTTPS.
  bool tls() const { return tls_; }

  // Stops serving and joins the thread. Idempotent.
  void Stop();

 private:
  static std::string Pattern(const std::string& path);
  std::unique_ptr<httplib::Server> server_;
  std::thread thread_;
  int port_ = 0;
  bool tls_ = false;
};

}  // namespace slapse::server
