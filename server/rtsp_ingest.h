// RtspIngest: the server's one RTSP ingest port for every RTSP push session
// (GStreamer's gst-rtsp-server, RECORD mode, on its own GMainLoop thread).
//
// Each push session is a mount at "/sessions/<id>/<path>" (its ingest_url),
// open to one publisher that authenticates with the session's own Digest
// credentials (user = the session id, password = HMAC-SHA256 of the session
// name under the server's ingest key, so a restart gives the same
// credentials without storing them). The publisher's RTP is depayloaded and
// parsed, not decoded (parsebin: H.264, MPEG-4 Part 2, MPEG-2 video), muxed
// into MPEG-TS and handed as bytes to the session's MvReader through an
// UploadQueue, as an upload's bytes are (server/source_upload.cc).
//
// What a publisher sees: an unknown path 404; no or wrong credentials 401;
// another session's valid credentials 404 (the path is not theirs to see); a
// second publisher to a path that already has one (or had one: a session
// takes one connection) 503, checked once it has authenticated. None of
// these touches the session.
//
// How a publisher's connection ends is recorded on its mount: TEARDOWN
// (clean end) or the connection lost without one (killed camera, network
// cut); the bytes sent before either are all delivered first.
//
// Thread-safety: every method may be called from any thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "core/common/status.h"
#include "server/udp_ports.h"
#include "server/upload_queue.h"

namespace slapse::server {

struct RtspIngestOptions {
  // Address the RTSP server binds and that ingest URLs name.
  std::string host = "127.0.0.1";
  // The host ingest URLs name instead of `host`, when cameras reach the port
  // by another name (a Kubernetes pod's stable DNS name, a per-replica
  // load balancer, NAT): a DNS name or an IPv4 address; "" = `host`.
  std::string url_host;
  // TCP port; 0 = a free one (RtspIngest::port()).
  int port = 0;
  // Secret the publish passwords derive from (LoadOrCreateRtspIngestKey).
  std::string key;
  // Bytes buffered per session between the RTSP pipeline and the MvReader.
  int64_t buffer_bytes = 4 << 20;
  // The server's UDP ports (RTP, RTCP) of a publisher that records over UDP
  // come from this range (gst-rtsp-server's address pool); any = the
  // kernel's choice. TCP-interleaved publishers use the RTSP port only.
  UdpPortRange rtp_ports;
};

// A session's publish credentials (RTSP Digest authentication).
struct RtspPublishCredentials {
  std::string username;
  std::string password;
};

// One push session's mount: its publisher's bytes and how the publisher ended.
class RtspPublishMount {
 public:
  enum class End { kNone, kTeardown, kLost };
  explicit RtspPublishMount(int64_t buffer_bytes);
  // The publisher's stream as MPEG-TS bytes: end of stream once the
  // publisher is gone (TEARDOWN or lost; end() says which).
  const std::shared_ptr<UploadQueue>& bytes() const { return bytes_; }
  End end() const { return end_.load(); }

  // The ingest server's side (rtsp_ingest.cc).
  bool Claim() { return !claimed_.exchange(true); }
  bool claimed() const { return claimed_.load(); }
  void SawTeardown() { teardown_ = true; }
  bool saw_teardown() const { return teardown_.load(); }
  bool had_publisher() const { return had_publisher_.load(); }
  void SetHadPublisher() { had_publisher_ = true; }
  // The publisher's pipeline ended: records how, ends the byte stream.
  void PublisherGone();

 private:
  std::shared_ptr<UploadQueue> bytes_;
  std::atomic<bool> claimed_{false};
  std::atomic<bool> teardown_{false};
  std::atomic<bool> had_publisher_{false};
  std::atomic<End> end_{End::kNone};
};

class RtspIngest {
 public:
  // Binds options.host:options.port and starts serving. UNAVAILABLE if the
  // port cannot be bound (in use), naming it and the flag.
  static StatusOr<std::unique_ptr<RtspIngest>> Start(const RtspIngestOptions& options);
  // Unmounts everything (publishers are disconnected) and stops the loop.
  ~RtspIngest();
  RtspIngest(const RtspIngest&) = delete;
  RtspIngest& operator=(const RtspIngest&) = delete;

  int port() const { return port_; }

  // Mounts session `session_name` ("sessions/<id>") at
  // /sessions/<id>/<path> and returns its ingest_url (no credentials in it).
  // A session already mounted is mounted again (a restart's resume).
  StatusOr<std::string> Mount(const std::string& session_name, const std::string& path);
  // The session's publish credentials (the same for the life of the key).
  RtspPublishCredentials Credentials(const std::string& session_name) const;

  // The mount of a session, from any server of the process (session names
  // are unique); null if none.
  static std::shared_ptr<RtspPublishMount> FindMount(const std::string& session_name);
  // Unmounts a session wherever it is mounted: the path then answers 404,
  // its publisher (if any) is disconnected unless it sent TEARDOWN (it is
  // being answered and closes its connection itself), its bytes end.
  // Idempotent.
  static void Unmount(const std::string& session_name);

  struct Impl;

 private:
  explicit RtspIngest(std::unique_ptr<Impl> impl);
  void UnmountOwn(const std::string& session_name);

  std::unique_ptr<Impl> impl_;
  int port_ = 0;
};

// The secret publish passwords derive from: read from `data_dir`/rtsp_ingest.key
// (created with 32 random bytes, mode 0600, if missing), so credentials survive
// a restart; a fresh random key for an in-memory data dir (kInMemoryDataDir).
StatusOr<std::string> LoadOrCreateRtspIngestKey(const std::string& data_dir);

// "rtsp://HOST:PORT/PATH" with `credentials` put in as user:password@, for
// publishers that take credentials in the URL (ffmpeg, rtspclientsink). The
// user and password are URL-safe ([a-z0-9-]). Without credentials (e.g. an
// older server's response) the URL as it is.
std::string RtspPublishUrl(const std::string& ingest_url, const RtspPublishCredentials& c);

}  // namespace slapse::server
