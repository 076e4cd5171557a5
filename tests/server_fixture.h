// Shared by the tests that run a real slapse server on loopback
// (server_test, fault_catalogue_test): ffmpeg as a camera, local ports.
#pragma once

#include <chrono>
#include <string>
#include <vector>

#include "client/lib/client.h"
#include "tests/test_streams.h"

namespace slapse::testing {

// Every rpc of these tests has a deadline; a hang fails, it does not block ctest.
client::ClientOptions TestClientOptions();

// A child `ffmpeg` (the camera) run with -nostdin -loglevel error, killed
// and reaped with the test (testing::ChildProcess).
class FfmpegProcess : public ChildProcess {
 public:
  explicit FfmpegProcess(const std::vector<std::string>& args);
};

// True once a local socket of `kind` ("tcp" in LISTEN, or "udp") has `port`,
// read from /proc/net (no connection attempt, which would use up the RTSP
// listener's single accept). Polls until `timeout`.
bool WaitForLocalPort(const std::string& kind, int port, std::chrono::milliseconds timeout);

// An even UDP port p with p and p + 1 free (RTP and RTCP), or 0.
int FreeRtpPort();

// The SDP `ffmpeg -f rtp -sdp_file` writes for MPEG-2 video (static payload
// type 32) sent to 127.0.0.1:port.
std::string Mpeg2RtpSdp(int port);

// The port of "rtsp://host:port/path".
int PortOf(const std::string& url);

// RTSP push: the URL a publisher (ffmpeg) uses for the session CreateSession
// returned, its publish credentials put in (user:password@).
std::string PublishUrl(const v1::Session& created);

// Sends one RTSP request (`method` on `url`, with an SDP body for ANNOUNCE)
// to 127.0.0.1:port on a connection of its own and returns the status code
// of the answer (e.g. 401, 404), or -1 if none came within 5 s.
int RtspRequestStatus(int port, const std::string& method, const std::string& url,
                      const std::string& sdp = "");

}  // namespace slapse::testing
