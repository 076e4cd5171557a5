// The UDP ports this server receives RTP on, as one configured range
// (`slapse serve --rtp-ports MIN-MAX`, docs/DEPLOY.md): the m=video port of
// every RTP/SDP session (and its RTCP port, the next one) must lie in it, and
// the RTSP ingest gives publishers that RECORD over UDP their server ports
// from it. A container or pod publishes exactly this range; TCP-interleaved
// RTSP needs none of it.
#pragma once

#include <string>

#include "core/common/status.h"

namespace slapse::server {

struct UdpPortRange {
  // Inclusive bounds; both 0 = any port (no range configured).
  int min_port = 0;
  int max_port = 0;

  bool any() const { return min_port == 0 && max_port == 0; }
  // Whether `port` may be used (always, without a range).
  bool Contains(int port) const { return any() || (port >= min_port && port <= max_port); }
  // "40000-40099", or "any".
  std::string ToString() const;
};

// Parses "MIN-MAX" (1024 <= MIN, MIN even, MAX odd, MIN < MAX <= 65535, so
// the range holds whole RTP/RTCP pairs) or "" / "any" (no range).
// INVALID_ARGUMENT naming the rule broken.
StatusOr<UdpPortRange> ParseUdpPortRange(const std::string& text);

}  // namespace slapse::server
