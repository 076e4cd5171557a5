// The RTSP pull source: the session connects to an RTSP server (FFmpeg's RTSP
// client: DESCRIBE / SETUP / PLAY, RTP interleaved on the TCP connection)
// and, when the connection ends or cannot be made, connects again after a
// growing wait while its ReconnectPolicy allows; frames flowing end an
// outage. Each attempt emits a Reconnecting event.
//
// How a connection that delivered video ends:
//   the camera ended the stream  FFmpeg's end of input (after an RTCP BYE on
//                                the stream) and the camera still answers on
//                                its RTSP connection (MvReaderOptions::
//                                check_source_at_end: PAUSE -> 200): FINISHED,
//                                whatever the reconnect policy
//   the camera was lost          the connection closed (killed camera: the
//                                same end of input from FFmpeg, but no answer)
//                                or no video for receive_timeout_ms: an
//                                outage; reconnects by the policy, then FAILED
//                                UNAVAILABLE "camera lost ..."
// A connection that cannot be made or delivers nothing is retried the same
// way; with no retries left the session FAILS with the last error.
#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <mutex>

#include "api/validate.h"
#include "server/ingest_source.h"

namespace slapse::server {
namespace {

// The wait before retry `attempt` (1, 2, ...) of an outage, ms.
int ReconnectDelayMs(const v1::ReconnectPolicy& p, int attempt) {
  const double initial =
      p.initial_interval_ms() > 0 ? p.initial_interval_ms() : api::kDefaultReconnectIntervalMs;
  const double factor =
      p.backoff_multiplier() > 0 ? p.backoff_multiplier() : api::kDefaultBackoffMultiplier;
  const double cap = p.max_interval_ms() > 0
                         ? p.max_interval_ms()
                         : std::max<double>(api::kDefaultMaxReconnectIntervalMs, initial);
  double delay = initial;
  for (int k = 1; k < attempt && delay < cap; ++k) delay *= factor;
  return static_cast<int>(std::min(delay, cap));
}

class RtspPullSource : public IngestSource {
 public:
  explicit RtspPullSource(const v1::RtspPull& pull)
      : IngestSource(pull.start_timeout_ms(), pull.receive_timeout_ms()),
        url_(pull.url()),
        shown_url_(api::RedactUrl(pull.url())),
        policy_(pull.reconnect()) {}

  StatusOr<std::unique_ptr<MvReader>> Open(std::function<bool()> interrupt) override;
  std::optional<int> AfterConnection(Session* session, const ConnectionEnd& end) override;

 private:
  // Why connection `end` ended, for events and messages.
  std::string Reason(const ConnectionEnd& end) const;
  // Ends the session when the policy has no retry left.
  void GiveUp(Session* session, const std::string& reason) const;

  const std::string url_;
  const std::string shown_url_;  // without credentials
  const v1::ReconnectPolicy policy_;
  int attempt_ = 0;     // retries in the current outage
  std::string lost_;    // the current outage began with "camera lost ..." (Reason), or ""
  int reconnects_ = 0;  // retries over the session's life
};

StatusOr<std::unique_ptr<MvReader>> RtspPullSource::Open(std::function<bool()> interrupt) {
  // "timeout" is FFmpeg's socket I/O timeout (connect and reads) in
  // microseconds; the interrupt callback bounds the rest.
  MvReaderOptions o = ReaderOptions(std::move(interrupt));
  o.format = "rtsp";
  o.check_source_at_end = true;  // a closed connection is a lost camera, not an end
  o.format_options = {{"rtsp_transport", "tcp"},
                      {"allowed_media_types", "video"},
                      {"timeout", std::to_string(int64_t{receive_timeout_ms()} * 1000)}};
  auto reader = MvReader::Open(url_, o);
  if (reader.ok()) return reader;
  // FFmpeg's messages quote the URL: drop its credentials.
  std::string message = reader.status().message();
  for (size_t at = message.find(url_); at != std::string::npos;
       at = message.find(url_, at + shown_url_.size())) {
    message.replace(at, url_.size(), shown_url_);
  }
  return Status(reader.status().code(), message);
}

// A clean end (the camera still answered after FFmpeg's end of input).
bool EndedByCamera(const ConnectionEnd& end) {
  return end.frames > 0 && !end.timed_out && end.status.code() == StatusCode::kOutOfRange;
}

// A connection that delivered video and then lost the camera.
bool LostCamera(const ConnectionEnd& end) {
  return end.frames > 0 && (end.timed_out || end.status.code() == StatusCode::kUnavailable);
}

std::string RtspPullSource::Reason(const ConnectionEnd& end) const {
  const std::string frames = std::to_string(end.frames) + " frames";
  if (end.timed_out && end.frames == 0) {
    return "no video within start_timeout_ms=" + std::to_string(start_timeout_ms()) +
           " of connecting";
  }
  if (end.timed_out) {
    return "camera lost: no video for receive_timeout_ms=" + std::to_string(receive_timeout_ms()) +
           " after " + frames;
  }
  if (LostCamera(end)) return "camera lost after " + frames + ": " + end.status.message();
  return end.status.message();
}

void RtspPullSource::GiveUp(Session* s, const std::string& reason) const {
  if (policy_.max_attempts() == 0) {
    s->End({v1::Session::FAILED,
            UnavailableError("rtsp_pull '" + shown_url_ + "': " + reason +
                             " (no reconnect: reconnect.max_attempts is 0)"),
            ""});
    return;
  }
  s->End(
      {v1::Session::FAILED,
       UnavailableError("rtsp_pull '" + shown_url_ + "': " + (lost_.empty() ? "" : lost_ + "; ") +
                        "gave up after " + std::to_string(attempt_) +
                        " reconnect attempt(s); last error: " + reason),
       ""});
}

std::optional<int> RtspPullSource::AfterConnection(Session* s, const ConnectionEnd& end) {
  if (s->stop) {
    s->EndStream(CancelledError("stopped"), "");
    return std::nullopt;
  }
  if (end.status.code() == StatusCode::kFailedPrecondition) {  // an unusable stream
    s->EndStream(end.status, "");
    return std::nullopt;
  }
  if (EndedByCamera(end)) {
    s->End({v1::Session::FINISHED, Status::Ok(),
            "the stream ended: the camera ended it after " + std::to_string(end.frames) +
                " frames of this connection (end of stream, RTCP BYE, with the camera "
                "still answering on its RTSP connection)"});
    return std::nullopt;
  }
  if (end.frames > 0) attempt_ = 0;  // frames flowed: an outage is over
  const std::string reason = Reason(end);
  if (attempt_ == 0) lost_ = LostCamera(end) ? reason : "";
  if (attempt_ >= policy_.max_attempts()) {
    GiveUp(s, reason);
    return std::nullopt;
  }
  ++attempt_;
  ++reconnects_;
  const int delay_ms = ReconnectDelayMs(policy_, attempt_);
  {
    std::lock_guard<std::mutex> lock(s->mu);
    s->proto.mutable_stats()->set_reconnects(reconnects_);
    *s->proto.mutable_update_time() = google::protobuf::util::TimeUtil::GetCurrentTime();
  }
  v1::SessionEvent e;
  v1::Reconnecting* r = e.mutable_reconnecting();
  r->set_attempt(attempt_);
  r->set_max_attempts(policy_.max_attempts());
  r->set_delay_ms(delay_ms);
  r->set_reason(reason);
  s->events->Append(std::move(e));
  return delay_ms;
}

}  // namespace

std::unique_ptr<IngestSource> MakeRtspPullSource(const v1::RtspPull& pull) {
  return std::make_unique<RtspPullSource>(pull);
}

}  // namespace slapse::server
