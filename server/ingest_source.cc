#include "server/ingest_source.h"

#include "api/validate.h"

namespace slapse::server {

IngestSource::IngestSource(int start_timeout_ms, int receive_timeout_ms)
    : start_timeout_ms_(start_timeout_ms > 0 ? start_timeout_ms : api::kDefaultStartTimeoutMs),
      receive_timeout_ms_(receive_timeout_ms > 0 ? receive_timeout_ms
                                                 : api::kDefaultReceiveTimeoutMs) {}

std::unique_ptr<IngestSource> IngestSource::Make(const v1::Session& request,
                                                 std::shared_ptr<UploadQueue> upload) {
  switch (request.source_case()) {
    case v1::Session::kRtspPull:
      return MakeRtspPullSource(request.rtsp_pull());
    case v1::Session::kRtspPush:
      return MakeRtspPushSource(request.rtsp_push(), request.ingest_url());
    case v1::Session::kRtpSdp:
      return MakeRtpSdpSource(request.rtp_sdp());
    default:
      return MakeUploadSource(std::move(upload));
  }
}

std::optional<int> SingleConnectionSource::AfterConnection(Session* session,
                                                           const ConnectionEnd& end) {
  // A deadline interrupts an open, or a read (which then reports CANCELLED).
  if (end.timed_out && (!end.opened || end.status.code() == StatusCode::kCancelled)) {
    session->End(TimedOut(end.session_frames));
  } else {
    session->EndStream(end.status, EndOfStreamMessage());
  }
  return std::nullopt;
}

}  // namespace slapse::server
