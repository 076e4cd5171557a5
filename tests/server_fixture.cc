#include "tests/server_fixture.h"

#include <fcntl.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <thread>
#include <utility>

#include "server/rtsp_ingest.h"

namespace slapse::testing {

// Every rpc of these tests has a deadline; a hang fails, it does not block ctest.
client::ClientOptions TestClientOptions() {
  client::ClientOptions o;
  o.rpc_timeout_s = 5;
  o.upload_timeout_s = 20;
  o.watch_timeout_s = 25;
  o.upload_chunk_bytes = 32 << 10;
  return o;
}

// A child `ffmpeg` (the camera) run with -nostdin -loglevel error, killed
// and reaped with the test (testing::ChildProcess).
FfmpegProcess::FfmpegProcess(const std::vector<std::string>& args) {
  std::vector<std::string> argv = {"ffmpeg", "-nostdin", "-loglevel", "error"};
  argv.insert(argv.end(), args.begin(), args.end());
  std::vector<char*> c;
  for (std::string& a : argv) c.push_back(a.data());
  c.push_back(nullptr);
  pid_ = fork();
  if (pid_ == 0) {
    const int null_fd = open("/dev/null", O_RDWR);
    dup2(null_fd, 0);
    dup2(null_fd, 1);  // the rtp muxer prints its SDP on stdout
    execvp("ffmpeg", c.data());
    _exit(127);
  }
}

// True once a local socket of `kind` ("tcp" in LISTEN, or "udp") has `port`,
// read from /proc/net (no connection attempt, which would use up the RTSP
// listener's single accept). Polls until `timeout`.
bool WaitForLocalPort(const std::string& kind, int port, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  char want[8];
  std::snprintf(want, sizeof(want), ":%04X", port);
  while (std::chrono::steady_clock::now() < deadline) {
    {
      const char* file = "/proc/net/";
      for (const std::string suffix : {"", "6"}) {
        std::ifstream in(std::string(file) + kind + suffix);
        std::string line;
        std::getline(in, line);  // header
        while (std::getline(in, line)) {
          std::istringstream fields(line);
          std::string slot, local, remote, state;
          fields >> slot >> local >> remote >> state;
          const bool port_ok = local.size() >= 5 && local.compare(local.size() - 5, 5, want) == 0;
          if (port_ok && (kind != "tcp" || state == "0A")) return true;
        }
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}

// An even UDP port p with p and p + 1 free (RTP and RTCP), or 0.
int FreeRtpPort() {
  auto bind_udp = [](int port) {
    const int fd = socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    sa.sin_port = htons(static_cast<uint16_t>(port));
    socklen_t len = sizeof(sa);
    int got = -1;
    if (bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) == 0 &&
        getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len) == 0) {
      got = ntohs(sa.sin_port);
    }
    return std::make_pair(fd, got);
  };
  for (int attempt = 0; attempt < 20; ++attempt) {
    auto [probe, any] = bind_udp(0);
    close(probe);
    if (any <= 0) continue;
    const int even = any & ~1;
    auto [a, pa] = bind_udp(even);
    auto [b, pb] = bind_udp(even + 1);
    close(a);
    close(b);
    if (pa == even && pb == even + 1) return even;
  }
  return 0;
}

// The SDP `ffmpeg -f rtp -sdp_file` writes for MPEG-2 video (static payload
// type 32) sent to 127.0.0.1:port.
std::string Mpeg2RtpSdp(int port) {
  return "v=0\r\no=- 0 0 IN IP4 127.0.0.1\r\ns=No Name\r\nc=IN IP4 127.0.0.1\r\nt=0 0\r\n"
         "m=video " +
         std::to_string(port) + " RTP/AVP 32\r\n";
}

// The port of "rtsp://host:port/path".
int PortOf(const std::string& url) {
  const size_t colon = url.rfind(':');
  return colon == std::string::npos ? 0 : std::atoi(url.c_str() + colon + 1);
}

std::string PublishUrl(const v1::Session& created) {
  return server::RtspPublishUrl(created.ingest_url(), {created.publish_credentials().username(),
                                                       created.publish_credentials().password()});
}

int RtspRequestStatus(int port, const std::string& method, const std::string& url,
                      const std::string& sdp) {
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(static_cast<uint16_t>(port));
  sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval tv{5, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  std::string request = method + " " + url + " RTSP/1.0\r\nCSeq: 1\r\n";
  if (!sdp.empty()) {
    request +=
        "Content-Type: application/sdp\r\nContent-Length: " + std::to_string(sdp.size()) + "\r\n";
  }
  request += "\r\n" + sdp;
  std::string answer;
  if (connect(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) == 0 &&
      send(fd, request.data(), request.size(), MSG_NOSIGNAL) ==
          static_cast<ssize_t>(request.size())) {
    char buf[512];
    while (answer.find("\r\n") == std::string::npos) {
      const ssize_t n = recv(fd, buf, sizeof(buf), 0);
      if (n <= 0) break;
      answer.append(buf, static_cast<size_t>(n));
    }
  }
  close(fd);
  // "RTSP/1.0 404 Not Found"
  const std::string prefix = "RTSP/1.0 ";
  if (answer.compare(0, prefix.size(), prefix) != 0) return -1;
  return std::atoi(answer.c_str() + prefix.size());
}

}  // namespace slapse::testing
