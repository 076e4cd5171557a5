#include "server/ingest_source.h"

#include "api/convert.h"
#include "api/validate.h"

namespace slapse::server {

IngestSource::IngestSource(int start_timeout_ms, int receive_timeout_ms)
    : start_timeout_ms_(start_timeout_ms > 0 ? start_timeout_ms : api::kDefaultStartTimeoutMs),
      receive_timeout_ms_(receive_timeout_ms > 0 ? receive_timeout_ms
                                                 : api::kDefaultReceiveTimeoutMs) {}

std::unique_ptr<IngestSource> IngestSource::Make(const v1::Session& request,
                                                 std::shared_ptr<UploadQueue> upload,
                                                 ReaderSettings settings) {
  std::unique_ptr<IngestSource> source;
  switch (request.source_case()) {
    case v1::Session::kRtspPull:
      source = MakeRtspPullSource(request.rtsp_pull());
      break;
    case v1::Session::kRtspPush:
      source = MakeRtspPushSource(request.name(), request.rtsp_push());
      break;
    case v1::Session::kRtpSdp:
      source = MakeRtpSdpSource(request.rtp_sdp());
      break;
    default:
      source = MakeUploadSource(std::move(upload));
      break;
  }
  source->reader_options_ = api::StreamOptionsFromProto(request.stream_options());
  // The dashboard's overlays draw over the anchors' luma (server/frame_overlays.h;
  // the runner keeps an anchor's only while someone asks, and drops the rest);
  // with `luma_wanted` the reader copies none while nobody asks.
  source->reader_options_.keep_luma = true;
  source->reader_options_.luma_wanted = std::move(settings.luma_wanted);
  source->reader_options_.probe_bytes = settings.probe_bytes;
  return source;
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
