#include "server/http_server.h"

#include <httplib.h>

namespace slapse::server {

HttpServer::HttpServer() : server_(std::make_unique<httplib::Server>()) {
  // httplib's default also sets SO_REUSEPORT, which lets a second server bind
  // the same port and take half the scrapes: address reuse only (restarts).
  server_->set_socket_options([](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
}

HttpServer::~HttpServer() { Stop(); }

void HttpServer::Get(const std::string& path, HttpHandler handler) {
  // httplib matches patterns as regular expressions: quote the path's dots.
  std::string pattern;
  for (char c : path) {
    if (std::string("\\^$.|?*+()[]{}").find(c) != std::string::npos) pattern += '\\';
    pattern += c;
  }
  server_->Get(pattern,
               [handler = std::move(handler)](const httplib::Request& req, httplib::Response& res) {
                 HttpRequest request;
                 request.path = req.path;
                 for (const auto& [k, v] : req.params) request.params.emplace(k, v);
                 HttpResponse response = handler(request);
                 res.status = response.status;
                 res.set_content(std::move(response.body), response.content_type.c_str());
               });
}

Status HttpServer::Start(const std::string& address, int port) {
  if (port < 0 || port > 65535) {
    return InvalidArgumentError("HTTP port must be in [0, 65535], got " + std::to_string(port));
  }
  if (port == 0) {
    port_ = server_->bind_to_any_port(address);
  } else {
    port_ = server_->bind_to_port(address, port) ? port : -1;
  }
  if (port_ <= 0) {
    port_ = 0;
    return UnavailableError("HTTP: cannot listen on " + address + ":" + std::to_string(port) +
                            " (in use, or not a local address?)");
  }
  thread_ = std::thread([this] { server_->listen_after_bind(); });
  return Status::Ok();
}

void HttpServer::Stop() {
  if (!thread_.joinable()) return;
  server_->stop();
  thread_.join();
}

}  // namespace slapse::server
