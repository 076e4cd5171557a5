// Fuzzes the checks of what a client sends for network sources:
// api::ValidateSdp (an RtpSdp request's session description) and
// api::ValidateRtspUrl + api::RedactUrl (an RtspPull request's URL).
//
// The input's first byte picks the target; the rest is the text:
//   even:  ValidateSdp(text). Invariant: an accepted SDP is within
//          kMaxSdpBytes, has no NUL, starts with "v=0" and has an m=video line.
//   odd:   the text is split at its first '\n' into a prefix and a user name;
//          the URL is  <prefix>://<user>:S3CR3T@<rest of the text> .
//          Invariants: RedactUrl(url) and ValidateRtspUrl(url)'s message never
//          contain the planted password (unless the fuzzed parts spell it
//          themselves), whenever the user name is a valid userinfo (no
//          '/', '?', '#') and the prefix holds no "://"; RedactUrl is
//          idempotent and leaves a URL without '@' and '=' unchanged.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "api/validate.h"

namespace {

constexpr char kSecret[] = "S3CR3T";

void Check(bool ok, const char* what, const std::string& input) {
  if (ok) return;
  std::fprintf(stderr, "fuzz_sdp_url: invariant violated: %s\ninput: '%s'\n", what, input.c_str());
  std::abort();
}

bool Contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

void FuzzSdp(const std::string& sdp) {
  const slapse::Status s = slapse::api::ValidateSdp(sdp);
  if (!s.ok()) {
    Check(!s.message().empty(), "an SDP refused without a message", sdp);
    return;
  }
  Check(sdp.size() <= slapse::api::kMaxSdpBytes, "an SDP over the size limit accepted", sdp);
  Check(!Contains(sdp, std::string(1, '\0')), "an SDP with a NUL accepted", sdp);
  Check(Contains(sdp, "v=0"), "an SDP without v=0 accepted", sdp);
  Check(Contains(sdp, "m=video "), "an SDP without m=video accepted", sdp);
}

void FuzzUrl(const std::string& text) {
  const size_t nl = text.find('\n');
  const std::string prefix = nl == std::string::npos ? "rtsp" : text.substr(0, nl);
  const std::string rest = nl == std::string::npos ? text : text.substr(nl + 1);
  const size_t nl2 = rest.find('\n');
  const std::string user = nl2 == std::string::npos ? "user" : rest.substr(0, nl2);
  const std::string host = nl2 == std::string::npos ? rest : rest.substr(nl2 + 1);
  const std::string url = prefix + "://" + user + ":" + kSecret + "@" + host;

  const std::string redacted = slapse::api::RedactUrl(url);
  Check(slapse::api::RedactUrl(redacted) == redacted, "RedactUrl is not idempotent", url);
  if (!Contains(text, "@") && !Contains(text, "=")) {
    Check(slapse::api::RedactUrl(text) == text, "URL without @ or = changed", text);
  }
  const slapse::Status s = slapse::api::ValidateRtspUrl(url);
  const bool planted = !Contains(prefix, "://") && user.find_first_of("/?#") == std::string::npos &&
                       !Contains(prefix + user + host, kSecret);
  if (!planted) return;
  Check(!Contains(redacted, kSecret), "RedactUrl kept the password", url);
  Check(!Contains(s.message(), kSecret), "ValidateRtspUrl's message shows the password", url);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] % 2 == 0) {
    FuzzSdp(text);
  } else {
    FuzzUrl(text);
    // The URL as typed, too: it must be checked without crashing.
    (void)slapse::api::ValidateRtspUrl(text);
  }
  return 0;
}
