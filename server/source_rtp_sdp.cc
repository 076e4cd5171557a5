// The RTP/SDP source: RTP packets (UDP) as the client's SDP describes them,
// from the senders of RtpSdp.allowed_senders only (when given).
// RTP has no end-of-stream, so a session that got video FINISHES when
// none arrived for receive_timeout_ms; none within start_timeout_ms FAILS it.
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <cstdlib>

#include "server/ingest_source.h"

namespace slapse::server {

namespace {

// The port of the SDP's m=video line (validated: 1..65535), or 0.
int SdpVideoPort(const std::string& sdp) {
  const size_t at = sdp.find("m=video ");
  if (at == std::string::npos) return 0;
  return static_cast<int>(std::strtol(sdp.c_str() + at + 8, nullptr, 10));
}

// 0 if UDP `port` can be bound on every address, else the errno.
int TryBindUdp(int port) {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  if (fd < 0) return errno;
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_addr.s_addr = htonl(INADDR_ANY);
  sa.sin_port = htons(static_cast<uint16_t>(port));
  const int rc = bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa));
  const int err = rc == 0 ? 0 : errno;
  close(fd);
  return err;
}

}  // namespace

Status CheckRtpPortsFree(const std::string& sdp) {
  const int port = SdpVideoPort(sdp);
  if (port <= 0) return Status::Ok();  // ValidateSdp has the say
  for (int p : {port, port + 1}) {
    if (p > 65535) break;
    const int err = TryBindUdp(p);
    if (err == 0) continue;
    const std::string role = p == port ? "RTP port" : "RTCP port (the RTP port + 1)";
    return FailedPreconditionError(
        "rtp_sdp.sdp: UDP " + role + " " + std::to_string(p) + " of the m=video line (" +
        std::to_string(port) + ") cannot be bound on this server: " + std::strerror(err) +
        (err == EADDRINUSE ? " (another session or program receives there); pick a free even "
                             "port in the SDP and send there"
                           : ""));
  }
  return Status::Ok();
}

Status CheckRtpPortsInRange(const std::string& sdp, const UdpPortRange& range) {
  const int port = SdpVideoPort(sdp);
  if (port <= 0 || range.any()) return Status::Ok();  // ValidateSdp has the say on the port
  if (range.Contains(port) && range.Contains(port + 1)) return Status::Ok();
  return InvalidArgumentError("rtp_sdp.sdp: the m=video port " + std::to_string(port) +
                              " (RTP, and RTCP on " + std::to_string(port + 1) +
                              ") is outside this server's RTP port range " + range.ToString() +
                              " (serve --rtp-ports): pick an even port in it and send there");
}

namespace {

// `sdp` with the sender allow-list as RFC 4570 source-filter lines (one per
// address family) before its first m= line, so they apply to every stream.
// FFmpeg's SDP demuxer turns them into the RTP input's "sources" option,
// which drops packets from any other address.
std::string WithSourceFilter(const std::string& sdp,
                             const google::protobuf::RepeatedPtrField<std::string>& allowed) {
  if (allowed.empty()) return sdp;
  std::string v4, v6;
  for (const std::string& a : allowed) (a.find(':') == std::string::npos ? v4 : v6) += " " + a;
  std::string lines;
  if (!v4.empty()) lines += "a=source-filter: incl IN IP4 *" + v4 + "\r\n";
  if (!v6.empty()) lines += "a=source-filter: incl IN IP6 *" + v6 + "\r\n";
  size_t at = sdp.find("\nm=");
  at = sdp.compare(0, 2, "m=") == 0 ? 0 : (at == std::string::npos ? sdp.size() : at + 1);
  return sdp.substr(0, at) + lines + sdp.substr(at);
}

class RtpSdpSource : public SingleConnectionSource {
 public:
  explicit RtpSdpSource(const v1::RtpSdp& rtp)
      : SingleConnectionSource(rtp.start_timeout_ms(), rtp.receive_timeout_ms()),
        sdp_(WithSourceFilter(rtp.sdp(), rtp.allowed_senders())) {}

  // The SDP goes to a private temp file (mkstemp: mode 0600) that is removed
  // once FFmpeg has parsed it; only file, udp and rtp are allowed.
  StatusOr<std::unique_ptr<MvReader>> Open(std::function<bool()> interrupt) override {
    SLAPSE_RETURN_IF_ERROR(CheckRtpPortsFree(sdp_));
    const char* tmp = std::getenv("TMPDIR");
    std::string path =
        std::string(tmp != nullptr && *tmp != '\0' ? tmp : "/tmp") + "/slapse-sdp-XXXXXX";
    const int fd = mkstemp(path.data());
    if (fd < 0) return UnavailableError("cannot create a temp file for the SDP");
    size_t done = 0;
    while (done < sdp_.size()) {
      const ssize_t n = write(fd, sdp_.data() + done, sdp_.size() - done);
      if (n <= 0) break;
      done += static_cast<size_t>(n);
    }
    close(fd);
    if (done != sdp_.size()) {
      unlink(path.c_str());
      return UnavailableError("cannot write the SDP to a temp file");
    }
    MvReaderOptions o = ReaderOptions(std::move(interrupt));
    o.format = "sdp";
    o.format_options = {{"protocol_whitelist", "file,udp,rtp"}, {"allowed_media_types", "video"}};
    auto reader = MvReader::Open(path, o);
    unlink(path.c_str());
    return reader;
  }

 protected:
  Ending TimedOut(int64_t session_frames) const override {
    if (session_frames == 0) {
      return {
          v1::Session::FAILED,
          Status(StatusCode::kDeadlineExceeded, "no RTP video arrived within start_timeout_ms=" +
                                                    std::to_string(start_timeout_ms())),
          ""};
    }
    return {v1::Session::FINISHED, Status::Ok(),
            "no RTP video for receive_timeout_ms=" + std::to_string(receive_timeout_ms()) +
                ": the stream is taken as ended"};
  }

 private:
  const std::string sdp_;
};

}  // namespace

std::unique_ptr<IngestSource> MakeRtpSdpSource(const v1::RtpSdp& rtp) {
  return std::make_unique<RtpSdpSource>(rtp);
}

}  // namespace slapse::server
