// IngestSource: where a session's stream comes from, one implementation per
// kind, each in its own file:
//   source_upload.cc     the client's UploadStream bytes (no deadlines)
//   source_rtsp_pull.cc  an RTSP server the session connects to, reconnecting
//                        on an outage by its ReconnectPolicy
//   source_rtsp_push.cc  an RTSP publisher on the server's one RTSP ingest port
//                        (server/rtsp_ingest.h), at the session's ingest_url
//   source_rtp_sdp.cc    RTP packets described by an SDP
// A source knows how to open its reader (one connection), its deadlines and
// how a connection's end reads: it ends the session (Session::End /
// EndStream) or asks for another connection after a wait. The session runner
// (server/session_runner.cc) does the rest.
//
// Deadlines of network sources: start_timeout_ms from each connection attempt
// until its first frame, then receive_timeout_ms per frame read (time blocked
// in I/O); the runner's interrupt callback enforces them.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "core/common/status.h"
#include "core/mv/mv_reader.h"
#include "server/session.h"
#include "server/udp_ports.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::server {

// How one connection of a session ended.
struct ConnectionEnd {
  Status status;               // why it ended, or why it could not be opened
  bool opened = false;         // the reader opened
  bool timed_out = false;      // a deadline interrupted it
  int64_t frames = 0;          // frames this connection delivered
  int64_t session_frames = 0;  // frames over the session's life
};

// What the server sets on every session's reader, besides the session's own
// stream options.
struct ReaderSettings {
  int64_t probe_bytes = 0;            // MvReaderOptions::probe_bytes
  std::function<bool()> luma_wanted;  // MvReaderOptions::luma_wanted
};

class IngestSource {
 public:
  // The source of `request` (a validated session, ingest_url assigned);
  // `upload` feeds an upload session.
  static std::unique_ptr<IngestSource> Make(const v1::Session& request,
                                            std::shared_ptr<UploadQueue> upload,
                                            ReaderSettings settings = {});
  virtual ~IngestSource() = default;

  // Network sources have deadlines; an upload does not.
  virtual bool network() const { return true; }
  int start_timeout_ms() const { return start_timeout_ms_; }
  int receive_timeout_ms() const { return receive_timeout_ms_; }

  // Opens one connection; `interrupt` returning true aborts blocking I/O.
  virtual StatusOr<std::unique_ptr<MvReader>> Open(std::function<bool()> interrupt) = 0;

  // The FINISHED message when the stream ends by itself (OUT_OF_RANGE).
  virtual std::string EndOfStreamMessage() const { return "the stream ended"; }

  // After connection `end`: ends `session` and returns nullopt, or returns
  // the wait in ms before the next connection (RTSP pull only).
  virtual std::optional<int> AfterConnection(Session* session, const ConnectionEnd& end) = 0;

 protected:
  // 0 = the defaults (api/validate.h).
  IngestSource(int start_timeout_ms, int receive_timeout_ms);
  // The session's stream options (Session.stream_options, e.g. re-encoding);
  // each source adds its format and interrupt to these.
  MvReaderOptions ReaderOptions(std::function<bool()> interrupt) const {
    MvReaderOptions o = reader_options_;
    o.interrupt = std::move(interrupt);
    return o;
  }

 private:
  int start_timeout_ms_;
  int receive_timeout_ms_;
  MvReaderOptions reader_options_;
};

// The one-connection sources (upload, RTSP push, RTP/SDP): a connection's end
// is the session's.
class SingleConnectionSource : public IngestSource {
 public:
  std::optional<int> AfterConnection(Session* session, const ConnectionEnd& end) override;

 protected:
  using IngestSource::IngestSource;
  // The ending after a deadline passed with `session_frames` read.
  virtual Ending TimedOut(int64_t session_frames) const = 0;
};

// The sources (one file each).
std::unique_ptr<IngestSource> MakeUploadSource(std::shared_ptr<UploadQueue> upload);
std::unique_ptr<IngestSource> MakeRtspPullSource(const v1::RtspPull& pull);
// RTSP push: the mount of session `session_name` (RtspIngest::Mount).
std::unique_ptr<IngestSource> MakeRtspPushSource(const std::string& session_name,
                                                 const v1::RtspPush& push);
std::unique_ptr<IngestSource> MakeRtpSdpSource(const v1::RtpSdp& rtp);

// RTP/SDP: FAILED_PRECONDITION naming the port if the UDP port of the SDP's
// m=video line (RTP) or the next one (RTCP) cannot be bound here (in use).
// At CreateSession and again when the session opens its receiver.
Status CheckRtpPortsFree(const std::string& sdp);
// RTP/SDP: INVALID_ARGUMENT naming the port and the range if the SDP's
// m=video port or the next one lies outside `range` (serve --rtp-ports).
Status CheckRtpPortsInRange(const std::string& sdp, const UdpPortRange& range);

}  // namespace slapse::server
