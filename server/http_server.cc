#include "server/http_server.h"

#include <httplib.h>

#include <chrono>
#include <thread>

namespace slapse::server {
namespace {

// Runs `handler` on an httplib request and fills httplib's response.
void Serve(const HttpHandler& handler, const httplib::Request& req, httplib::Response& res) {
  HttpRequest request;
  request.method = req.method;
  request.path = req.path;
  for (const auto& [k, v] : req.params) request.params.emplace(k, v);
  for (const auto& [k, v] : req.headers) request.headers.emplace(k, v);
  request.body = req.body;
  HttpResponse response = handler(request);
  res.status = response.status;
  for (const auto& [k, v] : response.headers) res.set_header(k.c_str(), v);
  if (!response.stream) {
    res.set_content(std::move(response.body), response.content_type.c_str());
    return;
  }
  res.set_chunked_content_provider(response.content_type, [stream = std::move(response.stream)](
                                                              size_t, httplib::DataSink& sink) {
    const HttpWrite write = [&sink](const std::string& chunk) {
      return sink.is_writable() && sink.write(chunk.data(), chunk.size());
    };
    if (!stream(write)) sink.done();
    return true;
  });
}

}  // namespace

std::string HttpRequest::Header(const std::string& name) const {
  for (const auto& [k, v] : headers) {
    if (k.size() == name.size() && std::equal(k.begin(), k.end(), name.begin(), [](char a, char b) {
          return std::tolower(a) == std::tolower(b);
        })) {
      return v;
    }
  }
  return "";
}

std::string HttpRequest::Param(const std::string& name) const {
  auto it = params.find(name);
  return it == params.end() ? "" : it->second;
}

HttpServer::HttpServer(const HttpTls& tls) : tls_(tls.on()) {
  if (tls_) {
    server_ = std::make_unique<httplib::SSLServer>(
        tls.cert_file.c_str(), tls.key_file.c_str(),
        tls.client_ca_file.empty() ? nullptr : tls.client_ca_file.c_str());
  } else {
    server_ = std::make_unique<httplib::Server>();
  }
  server_->new_task_queue = [] { return new httplib::ThreadPool(kHttpThreads); };
  // httplib's default also sets SO_REUSEPORT, which lets a second server bind
  // the same port and take half the scrapes: address reuse only (restarts).
  server_->set_socket_options([](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
}

HttpServer::~HttpServer() { Stop(); }

std::string HttpServer::Pattern(const std::string& path) {
  // httplib matches patterns as regular expressions: quote the path's dots.
  std::string pattern;
  for (char c : path) {
    if (std::string("\\^$.|?*+()[]{}").find(c) != std::string::npos) pattern += '\\';
    pattern += c;
  }
  return pattern;
}

void HttpServer::Get(const std::string& path, HttpHandler handler) {
  server_->Get(Pattern(path),
               [handler = std::move(handler)](const httplib::Request& req, httplib::Response& res) {
                 Serve(handler, req, res);
               });
}

void HttpServer::Post(const std::string& path, HttpHandler handler) {
  server_->Post(Pattern(path), [handler = std::move(handler)](const httplib::Request& req,
                                                              httplib::Response& res) {
    Serve(handler, req, res);
  });
}

Status HttpServer::Start(const std::string& address, int port) {
  if (port < 0 || port > 65535) {
    return InvalidArgumentError("HTTP port must be in [0, 65535], got " + std::to_string(port));
  }
  if (!server_->is_valid()) {
    return InvalidArgumentError(
        "HTTPS: cannot use the TLS certificate / key (or client CA) files: unreadable, not PEM, or "
        "the key does not match the certificate");
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
  // httplib's stop() only stops a server already in its accept loop: one
  // stopped right after Start() (before the thread got there) would listen
  // for ever. Wait until it runs (bounded: a listen that failed never runs),
  // then stop it.
  for (int waited_ms = 0; !server_->is_running() && waited_ms < 5000; ++waited_ms) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  server_->stop();
  thread_.join();
}

}  // namespace slapse::server
