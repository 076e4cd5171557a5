// The RTSP push source: the session's mount on the server's one RTSP ingest
// port (server/rtsp_ingest.h, gst-rtsp-server), named by its ingest_url, for
// one authenticated publisher (ANNOUNCE / SETUP / RECORD, then RTP over TCP
// or UDP). The mount's MPEG-TS bytes are read as an upload's are. The session
// FINISHES when the publisher sends TEARDOWN; it FAILS with UNAVAILABLE when
// the publisher's connection is lost without one or it goes quiet for
// receive_timeout_ms, and with DEADLINE_EXCEEDED when no publisher came
// within start_timeout_ms. The session's end unmounts it.
#include "server/ingest_source.h"
#include "server/rtsp_ingest.h"

namespace slapse::server {
namespace {

// The mount's bytes; `interrupt` (the runner's deadlines and stop) ends a
// wait for them.
class MountByteSource : public ByteSource {
 public:
  MountByteSource(std::shared_ptr<UploadQueue> bytes, std::function<bool()> interrupt)
      : bytes_(std::move(bytes)), interrupt_(std::move(interrupt)) {}
  int Read(uint8_t* buf, int size) override { return bytes_->Read(buf, size, interrupt_); }

 private:
  std::shared_ptr<UploadQueue> bytes_;
  std::function<bool()> interrupt_;
};

class RtspPushSource : public SingleConnectionSource {
 public:
  RtspPushSource(const std::string& session_name, const v1::RtspPush& push)
      : SingleConnectionSource(push.start_timeout_ms(), push.receive_timeout_ms()),
        session_name_(session_name),
        mount_(RtspIngest::FindMount(session_name)) {}
  ~RtspPushSource() override { RtspIngest::Unmount(session_name_); }

  StatusOr<std::unique_ptr<MvReader>> Open(std::function<bool()> interrupt) override {
    if (mount_ == nullptr) {
      return UnavailableError(
          "the session has no RTSP ingest mount (is the server's RTSP "
          "ingest running? serve --rtsp-port)");
    }
    MvReaderOptions o = ReaderOptions(interrupt);
    o.format = "mpegts";
    return MvReader::Open(std::make_unique<MountByteSource>(mount_->bytes(), interrupt), o);
  }

  std::string EndOfStreamMessage() const override {
    return "the publisher ended the stream (TEARDOWN)";
  }

  // The mount goes first, so the path answers 404 before the session's end
  // is announced.
  std::optional<int> AfterConnection(Session* session, const ConnectionEnd& end) override {
    RtspIngest::Unmount(session_name_);
    if (end.timed_out) {
      session->End(TimedOut(end.session_frames));
      return std::nullopt;
    }
    if (mount_ != nullptr && mount_->end() == RtspPublishMount::End::kLost) {
      session->End({v1::Session::FAILED,
                    UnavailableError("the RTSP publisher's connection was lost without a "
                                     "TEARDOWN (camera gone or network cut) after " +
                                     std::to_string(end.session_frames) + " frames"),
                    ""});
      return std::nullopt;
    }
    return SingleConnectionSource::AfterConnection(session, end);
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
  const std::string session_name_;
  const std::shared_ptr<RtspPublishMount> mount_;
};

}  // namespace

std::unique_ptr<IngestSource> MakeRtspPushSource(const std::string& session_name,
                                                 const v1::RtspPush& push) {
  return std::make_unique<RtspPushSource>(session_name, push);
}

}  // namespace slapse::server
