#include "server/udp_ports.h"

#include <cstdlib>

namespace slapse::server {

std::string UdpPortRange::ToString() const {
  if (any()) return "any";
  return std::to_string(min_port) + "-" + std::to_string(max_port);
}

StatusOr<UdpPortRange> ParseUdpPortRange(const std::string& text) {
  if (text.empty() || text == "any") return UdpPortRange{};
  const auto fail = [&](const std::string& why) {
    return InvalidArgumentError("RTP port range '" + text + "': " + why);
  };
  const size_t dash = text.find('-');
  if (dash == std::string::npos || dash == 0 || dash + 1 == text.size()) {
    return fail("expected MIN-MAX, e.g. 40000-40099");
  }
  for (size_t i = 0; i < text.size(); ++i) {
    if (i != dash && (text[i] < '0' || text[i] > '9')) return fail("expected MIN-MAX, digits only");
  }
  if (dash > 5 || text.size() - dash - 1 > 5) return fail("a port is at most 65535");
  UdpPortRange range;
  range.min_port = std::atoi(text.substr(0, dash).c_str());
  range.max_port = std::atoi(text.substr(dash + 1).c_str());
  if (range.max_port > 65535) return fail("a port is at most 65535");
  if (range.min_port < 1024) return fail("MIN must be 1024 or more (not a privileged port)");
  if (range.min_port >= range.max_port) return fail("MIN must be below MAX");
  if (range.min_port % 2 != 0 || range.max_port % 2 != 1) {
    return fail("MIN must be even and MAX odd, so the range holds whole RTP/RTCP port pairs");
  }
  return range;
}

}  // namespace slapse::server
