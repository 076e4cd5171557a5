// The RTP/SDP source: RTP packets (UDP) as the client's SDP describes them.
// RTP has no end-of-stream, so a session that got video FINISHES when
// none arrived for receive_timeout_ms; none within start_timeout_ms FAILS it.
#include <unistd.h>

#include <cstdlib>

#include "server/ingest_source.h"

namespace slapse::server {
namespace {

class RtpSdpSource : public SingleConnectionSource {
 public:
  explicit RtpSdpSource(const v1::RtpSdp& rtp)
      : SingleConnectionSource(rtp.start_timeout_ms(), rtp.receive_timeout_ms()), sdp_(rtp.sdp()) {}

  // The SDP goes to a private temp file (mkstemp: mode 0600) that is removed
  // once FFmpeg has parsed it; only file, udp and rtp are allowed.
  StatusOr<std::unique_ptr<MvReader>> Open(std::function<bool()> interrupt) override {
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
    MvReaderOptions o;
    o.interrupt = std::move(interrupt);
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
