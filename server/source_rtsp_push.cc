// The RTSP push source: the session listens (FFmpeg's RTSP demuxer in listen
// mode) on its own port of `rtsp_push_host`, named by its ingest_url, for one
// publisher (ANNOUNCE / SETUP / RECORD, then RTP over TCP or UDP). The
// session FINISHES when the publisher ends the stream and FAILS when no
// publisher came within start_timeout_ms or it went quiet for
// receive_timeout_ms.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "server/ingest_source.h"

namespace slapse::server {
namespace {

class RtspPushSource : public SingleConnectionSource {
 public:
  RtspPushSource(const v1::RtspPush& push, std::string ingest_url)
      : SingleConnectionSource(push.start_timeout_ms(), push.receive_timeout_ms()),
        ingest_url_(std::move(ingest_url)) {}

  StatusOr<std::unique_ptr<MvReader>> Open(std::function<bool()> interrupt) override {
    // "timeout" is FFmpeg's socket I/O timeout in microseconds.
    MvReaderOptions o = ReaderOptions(std::move(interrupt));
    o.format = "rtsp";
    o.format_options = {{"rtsp_flags", "listen"},
                        {"timeout", std::to_string(int64_t{receive_timeout_ms()} * 1000)}};
    return MvReader::Open(ingest_url_, o);
  }

  // FFmpeg's RTSP listener reports a TEARDOWN and a closed connection alike
  // (end of file), so both finish the session.
  std::string EndOfStreamMessage() const override {
    return "the publisher ended the stream (TEARDOWN or closed connection)";
  }

 protected:
  Ending TimedOut(int64_t session_frames) const override {
    if (session_frames == 0) {
      return {v1::Session::FAILED,
              Status(StatusCode::kDeadlineExceeded,
                     "no RTSP publisher sent video within start_timeout_ms=" +
                         std::to_string(start_timeout_ms())),
              ""};
    }
    return {v1::Session::FAILED,
            UnavailableError("the RTSP publisher sent nothing for receive_timeout_ms=" +
                             std::to_string(receive_timeout_ms())),
            ""};
  }

 private:
  const std::string ingest_url_;
};

// A free TCP port on `host`, from the kernel's ephemeral range. The port is
// released before FFmpeg binds it again; the kernel does not hand it out again
// right away, so the gap is harmless in practice.
StatusOr<int> PickFreeTcpPort(const std::string& host) {
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  if (inet_pton(AF_INET, host.c_str(), &sa.sin_addr) != 1) {
    return UnavailableError("rtsp_push_host '" + host + "' is not an IPv4 address");
  }
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return UnavailableError("no socket for an RTSP listener");
  socklen_t len = sizeof(sa);
  const bool ok = bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) == 0 &&
                  getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len) == 0;
  close(fd);
  if (!ok) return UnavailableError("no free port for an RTSP listener on " + host);
  return static_cast<int>(ntohs(sa.sin_port));
}

}  // namespace

std::unique_ptr<IngestSource> MakeRtspPushSource(const v1::RtspPush& push,
                                                 const std::string& ingest_url) {
  return std::make_unique<RtspPushSource>(push, ingest_url);
}

StatusOr<std::string> RtspPushIngestUrl(const std::string& host, const std::string& path) {
  auto port = PickFreeTcpPort(host);
  if (!port.ok()) return port.status();
  return "rtsp://" + host + ":" + std::to_string(*port) + "/" + path;
}

}  // namespace slapse::server
