#include "api/validate.h"

#include <arpa/inet.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "api/convert.h"
#include "api/list_query.h"
#include "core/common/angles.h"
#include "core/common/camera.h"

namespace slapse::api {
namespace {

bool Finite(double v) { return std::isfinite(v); }

// "A (1), B (2)" for the valid values of a proto enum.
template <typename Descriptor>
std::string EnumValues(const Descriptor* d) {
  std::string out;
  for (int i = 0; i < d->value_count(); ++i) {
    if (!out.empty()) out += ", ";
    out += d->value(i)->name() + " (" + std::to_string(d->value(i)->number()) + ")";
  }
  return out;
}

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

// Field of view across `size_px` pixels at focal length `f_px`: 2 atan(size / 2f).
double FovDeg(int size_px, double f_px) {
  return RadToDeg(2.0 * std::atan(size_px / (2.0 * f_px)));
}

// The focal length that gives `fov_deg` across `size_px` pixels (FovDeg's inverse).
double FocalForFovPx(int size_px, double fov_deg) {
  return size_px / (2.0 * std::tan(DegToRad(0.5 * fov_deg)));
}

// OK when the field of view `axis` ("horizontal" / "vertical") that focal
// length `focal_name` = f_px gives across size_px pixels is in [min_deg, max_deg].
Status CheckFov(const std::string& what, const std::string& focal_name, double f_px,
                const std::string& axis, int size_px, double min_deg, double max_deg,
                const std::string& image) {
  const double fov_deg = FovDeg(size_px, f_px);
  if (fov_deg >= min_deg && fov_deg <= max_deg) return Status::Ok();
  return InvalidArgumentError(what + ": " + focal_name + " " + Num(f_px) + " gives a " + axis +
                              " field of view of " + Num(fov_deg) + " deg on the " + image +
                              " image; want " + Num(min_deg) + " to " + Num(max_deg) + " deg (" +
                              focal_name + " about " + Num(FocalForFovPx(size_px, max_deg)) +
                              " to " + Num(FocalForFovPx(size_px, min_deg)) + ")");
}

}  // namespace

Status ValidateSourceTimeouts(int start_ms, int receive_ms, const std::string& what) {
  if (start_ms < 0 || receive_ms < 0) {
    return InvalidArgumentError(what +
                                ".start_timeout_ms and receive_timeout_ms must be >= 0 "
                                "(0 = the default)");
  }
  return Status::Ok();
}

Status ValidateRtspPushPath(const std::string& path) {
  bool ok = !path.empty() && path.size() <= 256 && path[0] != '/';
  for (char c : path) {
    ok = ok && (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-' ||
                c == '/');
  }
  if (!ok) {
    return InvalidArgumentError("rtsp_push.path '" + path +
                                "' is not a path: 1 to 256 of [A-Za-z0-9._-/], no leading '/'");
  }
  return Status::Ok();
}

bool IsSecretParamName(const std::string& name) {
  std::string n;
  for (char c : name) n += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  static const char* const kExact[] = {"token",
                                       "access_token",
                                       "id_token",
                                       "refresh_token",
                                       "key",
                                       "api_key",
                                       "apikey",
                                       "api-key",
                                       "password",
                                       "passwd",
                                       "pwd",
                                       "pass",
                                       "secret",
                                       "sig",
                                       "signature",
                                       "auth",
                                       "authorization",
                                       "credential",
                                       "credentials",
                                       "x-amz-signature",
                                       "x-amz-credential",
                                       "client_secret"};
  for (const char* e : kExact) {
    if (n == e) return true;
  }
  for (const std::string suffix : {"token", "secret", "password", "signature"}) {
    if (n.size() > suffix.size() &&
        n.compare(n.size() - suffix.size(), suffix.size(), suffix) == 0) {
      return true;
    }
  }
  return false;
}

namespace {

// `params` ("a=1&token=x", the text after '?' or '#') with the values of
// secret parameters replaced by ***.
std::string RedactParams(const std::string& params) {
  std::string out;
  size_t start = 0;
  while (start <= params.size()) {
    size_t end = params.find_first_of("&;", start);
    if (end == std::string::npos) end = params.size();
    const std::string part = params.substr(start, end - start);
    const size_t eq = part.find('=');
    if (eq != std::string::npos && IsSecretParamName(part.substr(0, eq))) {
      out += part.substr(0, eq + 1) + "***";
    } else {
      out += part;
    }
    if (end == params.size()) break;
    out += params[end];
    start = end + 1;
  }
  return out;
}

}  // namespace

namespace {

// One pass of RedactUrl: userinfo after every "://", then the parameters.
std::string RedactUrlOnce(const std::string& url) {
  std::string out = url;
  for (size_t scheme_end = out.find("://"); scheme_end != std::string::npos;
       scheme_end = out.find("://", scheme_end + 3)) {
    const size_t auth = scheme_end + 3;
    const size_t auth_end = std::min(out.find_first_of("/?#", auth), out.size());
    const size_t at = out.rfind('@', auth_end == 0 ? 0 : auth_end - 1);
    if (at != std::string::npos && at >= auth) out = out.substr(0, auth) + "***" + out.substr(at);
  }
  // The query and the fragment: name=value pairs.
  const size_t q = out.find_first_of("?#");
  if (q == std::string::npos) return out;
  std::string tail(1, out[q]);
  for (size_t start = q + 1;;) {
    const size_t hash = out.find('#', start);
    const size_t end = hash == std::string::npos ? out.size() : hash;
    tail += RedactParams(out.substr(start, end - start));
    if (end == out.size()) break;
    tail += '#';
    start = end + 1;
  }
  return out.substr(0, q) + tail;
}

}  // namespace

std::string RedactUrl(const std::string& url) {
  // To a fixed point: masking a parameter can remove a "://" whose userinfo
  // the pass had masked, so a later pass might see the text differently.
  // A text that needs more passes than kMaxRedactPasses (found by
  // fuzz_sdp_url: nested "://" and '@' that each pass uncovers one by one) is
  // masked whole, which is idempotent too.
  std::string out = RedactUrlOnce(url);
  for (int pass = 0; pass < kMaxRedactPasses; ++pass) {
    std::string next = RedactUrlOnce(out);
    if (next == out) return out;
    out = std::move(next);
  }
  return kRedactedUrl;
}

std::string RedactText(const std::string& text) {
  auto stop = [](char c) {
    return std::isspace(static_cast<unsigned char>(c)) || c == '\'' || c == '"' || c == '<' ||
           c == '>' || c == '`' || c == ')' || c == ']';
  };
  std::string out;
  size_t i = 0;
  while (i < text.size()) {
    const size_t sep = text.find("://", i);
    if (sep == std::string::npos) {
      out += text.substr(i);
      break;
    }
    // The scheme: the letters (and + - .) before "://".
    size_t begin = sep;
    while (begin > i &&
           (std::isalnum(static_cast<unsigned char>(text[begin - 1])) || text[begin - 1] == '+' ||
            text[begin - 1] == '-' || text[begin - 1] == '.')) {
      --begin;
    }
    size_t end = sep + 3;
    while (end < text.size() && !stop(text[end])) ++end;
    out += text.substr(i, begin - i) + RedactUrl(text.substr(begin, end - begin));
    i = end;
  }
  // name=value pairs outside URLs too (e.g. a URL cut at a space, or a
  // "token=..." in a library's message): secret names get *** as values.
  std::string pairs;
  size_t last = 0;
  for (size_t eq = out.find('='); eq != std::string::npos; eq = out.find('=', eq + 1)) {
    size_t name = eq;
    while (name > 0 && (std::isalnum(static_cast<unsigned char>(out[name - 1])) ||
                        out[name - 1] == '_' || out[name - 1] == '-')) {
      --name;
    }
    if (name == eq || name < last || !IsSecretParamName(out.substr(name, eq - name))) continue;
    size_t end = eq + 1;
    while (end < out.size() && !stop(out[end]) && out[end] != '&' && out[end] != ';' &&
           out[end] != '#' && out[end] != ',') {
      ++end;
    }
    if (end == eq + 1 || out.compare(eq + 1, end - eq - 1, "***") == 0) continue;
    pairs += out.substr(last, eq + 1 - last) + "***";
    last = end;
    eq = end - 1;
  }
  out = pairs + out.substr(last);
  // "Bearer <token>" -> "Bearer ***". The scheme as HTTP writes it
  // (capitalised): prose such as "a bearer token:" is left alone.
  std::string masked;
  size_t from = 0;
  for (size_t at = out.find("Bearer "); at != std::string::npos; at = out.find("Bearer ", at + 7)) {
    size_t v = at + 7, e = v;
    while (e < out.size() && !stop(out[e])) ++e;
    if (e == v || out.compare(v, e - v, "***") == 0) continue;
    masked += out.substr(from, v - from) + "***";
    from = e;
  }
  return masked + out.substr(from);
}

void RedactSession(v1::Session* s) {
  if (s->has_rtsp_pull()) s->mutable_rtsp_pull()->set_url(RedactUrl(s->rtsp_pull().url()));
  if (!s->ingest_url().empty()) s->set_ingest_url(RedactUrl(s->ingest_url()));
  if (s->has_error()) s->mutable_error()->set_message(RedactText(s->error().message()));
  s->set_state_message(RedactText(s->state_message()));
}

void RedactEvent(v1::SessionEvent* e) {
  if (e->has_state_change()) {
    e->mutable_state_change()->set_message(RedactText(e->state_change().message()));
  }
  if (e->has_reconnecting()) {
    e->mutable_reconnecting()->set_reason(RedactText(e->reconnecting().reason()));
  }
}

Status ValidateRtspUrl(const std::string& url) {
  auto bad = [&](const std::string& why) {
    return InvalidArgumentError("rtsp_pull.url '" + RedactUrl(url) + "' " + why +
                                "; want rtsp://host[:port]/path or rtsps://... (credentials as "
                                "user:password@ before the host)");
  };
  if (url.empty()) return InvalidArgumentError("rtsp_pull.url is required, e.g. rtsp://cam:554/1");
  if (url.size() > kMaxRtspUrlChars) return bad("is longer than 2048 characters");
  for (char c : url) {
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f) {
      return bad("contains a space or control character");
    }
  }
  const size_t scheme_end = url.find("://");
  std::string scheme = scheme_end == std::string::npos ? "" : url.substr(0, scheme_end);
  for (char& c : scheme) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (scheme != "rtsp" && scheme != "rtsps") return bad("does not start with rtsp:// or rtsps://");
  const size_t auth = scheme_end + 3;
  const size_t auth_end = std::min(url.find_first_of("/?#", auth), url.size());
  std::string hostport = url.substr(auth, auth_end - auth);
  const size_t at = hostport.rfind('@');
  if (at != std::string::npos) hostport = hostport.substr(at + 1);
  std::string host, port;
  if (!hostport.empty() && hostport[0] == '[') {
    const size_t close = hostport.find(']');
    if (close == std::string::npos) return bad("has an IPv6 host without its closing ']'");
    host = hostport.substr(1, close - 1);
    const std::string rest = hostport.substr(close + 1);
    if (!rest.empty() && rest[0] != ':') return bad("has characters after the IPv6 host");
    if (!rest.empty()) port = rest.substr(1);
    for (char c : host) {
      if (!std::isxdigit(static_cast<unsigned char>(c)) && c != ':' && c != '.') {
        return bad("has an IPv6 host with characters other than hex digits, ':' and '.'");
      }
    }
  } else {
    const size_t colon = hostport.find(':');
    host = hostport.substr(0, colon);
    if (colon != std::string::npos) port = hostport.substr(colon + 1);
    for (char c : host) {
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-' && c != '_') {
        return bad("has a host with characters other than letters, digits, '.', '-' and '_'");
      }
    }
  }
  if (host.empty()) return bad("has no host");
  if (!port.empty() || hostport.back() == ':') {
    bool digits = !port.empty() && port.size() <= 5;
    for (char c : port) digits = digits && std::isdigit(static_cast<unsigned char>(c));
    const long n = digits ? std::strtol(port.c_str(), nullptr, 10) : 0;
    if (n < 1 || n > 65535) return bad("has a port that is not 1..65535");
  }
  return Status::Ok();
}

Status ValidateReconnectPolicy(const v1::ReconnectPolicy& p) {
  auto bad = [](const std::string& why) {
    return InvalidArgumentError("rtsp_pull.reconnect." + why);
  };
  if (p.max_attempts() < 0 || p.max_attempts() > kMaxReconnectAttempts) {
    return bad("max_attempts must be in [0, 1000000] (0 = no reconnect), got " +
               std::to_string(p.max_attempts()));
  }
  if (p.initial_interval_ms() < 0 || p.initial_interval_ms() > kMaxReconnectIntervalMs) {
    return bad("initial_interval_ms must be in [0, 3600000] ms (0 = 1000), got " +
               std::to_string(p.initial_interval_ms()));
  }
  if (p.max_interval_ms() < 0 || p.max_interval_ms() > kMaxReconnectIntervalMs) {
    return bad("max_interval_ms must be in [0, 3600000] ms (0 = 30000), got " +
               std::to_string(p.max_interval_ms()));
  }
  const double m = p.backoff_multiplier();
  if (!Finite(m) || (m != 0 && (m < 1 || m > 100))) {
    return bad("backoff_multiplier must be in [1, 100] (0 = 2), got " + std::to_string(m));
  }
  if (p.max_interval_ms() > 0 && p.max_interval_ms() < p.initial_interval_ms()) {
    return bad("max_interval_ms (" + std::to_string(p.max_interval_ms()) +
               ") must be >= initial_interval_ms (" + std::to_string(p.initial_interval_ms()) +
               ")");
  }
  return Status::Ok();
}

// A light syntax check (RFC 4566): "v=0" first, every line "<letter>=...",
// a c= line and an m=video line with a port. FFmpeg's SDP parser accepts
// almost anything, so this is what turns a malformed SDP into INVALID_ARGUMENT.
Status ValidateAllowedSenders(const v1::RtpSdp& rtp) {
  if (rtp.allowed_senders_size() > kMaxAllowedSenders) {
    return InvalidArgumentError("rtp_sdp.allowed_senders has " +
                                std::to_string(rtp.allowed_senders_size()) + " entries; at most " +
                                std::to_string(kMaxAllowedSenders));
  }
  for (int i = 0; i < rtp.allowed_senders_size(); ++i) {
    const std::string& a = rtp.allowed_senders(i);
    in6_addr buf{};
    if (inet_pton(AF_INET, a.c_str(), &buf) != 1 && inet_pton(AF_INET6, a.c_str(), &buf) != 1) {
      return InvalidArgumentError("rtp_sdp.allowed_senders[" + std::to_string(i) + "] '" + a +
                                  "' is not an IPv4 or IPv6 address (names are not resolved)");
    }
  }
  return Status::Ok();
}

Status ValidateSdp(const std::string& sdp) {
  auto bad = [](const std::string& why) { return InvalidArgumentError("rtp_sdp.sdp: " + why); };
  if (sdp.empty()) return bad("required (the session description text)");
  if (sdp.size() > kMaxSdpBytes) return bad("longer than 64 KiB");
  if (sdp.find('\0') != std::string::npos) return bad("contains a NUL byte");
  bool first = true, has_c = false, has_video = false;
  size_t pos = 0;
  while (pos < sdp.size()) {
    size_t eol = sdp.find('\n', pos);
    if (eol == std::string::npos) eol = sdp.size();
    std::string line = sdp.substr(pos, eol - pos);
    pos = eol + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    if (line.size() < 2 || line[1] != '=' || !std::islower(static_cast<unsigned char>(line[0]))) {
      return bad("line '" + line.substr(0, 40) + "' is not '<letter>=<value>'");
    }
    if (first && line != "v=0") return bad("must start with 'v=0'");
    first = false;
    if (line[0] == 'c') has_c = true;
    if (line.compare(0, 8, "m=video ") == 0) {
      const long port = std::strtol(line.c_str() + 8, nullptr, 10);
      if (port < 1 || port > 65535) return bad("m=video line without a port in 1..65535");
      has_video = true;
    }
  }
  if (!has_c) return bad("no connection line (c=IN IP4 <address>)");
  if (!has_video) return bad("no video media line (m=video <port> RTP/AVP <type>)");
  return Status::Ok();
}

Status ValidateSession(const v1::Session& r) {
  switch (r.source_case()) {
    case v1::Session::kUpload:
      break;
    case v1::Session::kRtspPull:
      SLAPSE_RETURN_IF_ERROR(ValidateRtspUrl(r.rtsp_pull().url()));
      SLAPSE_RETURN_IF_ERROR(ValidateReconnectPolicy(r.rtsp_pull().reconnect()));
      SLAPSE_RETURN_IF_ERROR(ValidateSourceTimeouts(
          r.rtsp_pull().start_timeout_ms(), r.rtsp_pull().receive_timeout_ms(), "rtsp_pull"));
      break;
    case v1::Session::kRtspPush:
      SLAPSE_RETURN_IF_ERROR(ValidateRtspPushPath(r.rtsp_push().path()));
      SLAPSE_RETURN_IF_ERROR(ValidateSourceTimeouts(
          r.rtsp_push().start_timeout_ms(), r.rtsp_push().receive_timeout_ms(), "rtsp_push"));
      break;
    case v1::Session::kRtpSdp:
      SLAPSE_RETURN_IF_ERROR(ValidateSdp(r.rtp_sdp().sdp()));
      SLAPSE_RETURN_IF_ERROR(ValidateAllowedSenders(r.rtp_sdp()));
      SLAPSE_RETURN_IF_ERROR(ValidateSourceTimeouts(r.rtp_sdp().start_timeout_ms(),
                                                    r.rtp_sdp().receive_timeout_ms(), "rtp_sdp"));
      break;
    case v1::Session::SOURCE_NOT_SET:
      return InvalidArgumentError(
          "session.source is required (upload, rtsp_pull, rtsp_push, rtp_sdp)");
  }
  if (!r.has_intrinsics()) {
    return InvalidArgumentError("session.intrinsics is required (fx_px, fy_px, cx_px, cy_px)");
  }
  SLAPSE_RETURN_IF_ERROR(ValidateIntrinsics(IntrinsicsFromProto(r.intrinsics()), "intrinsics"));
  const v1::Intrinsics& k = r.intrinsics();
  if (k.width_px() > 0 && k.height_px() > 0) {
    SLAPSE_RETURN_IF_ERROR(ValidateIntrinsicsForImage(
        k, k.width_px(), k.height_px(), "intrinsics (for their width_px x height_px)"));
  }
  SLAPSE_RETURN_IF_ERROR(ValidateLabels(r.labels()));
  return ValidatePipelineOptions(r.pipeline_options());
}

Status ValidateLabels(const google::protobuf::Map<std::string, std::string>& labels) {
  if (labels.size() > kMaxLabels) {
    return InvalidArgumentError("session.labels has " + std::to_string(labels.size()) +
                                " labels; at most " + std::to_string(kMaxLabels));
  }
  for (const auto& [key, value] : labels) {
    const bool key_ok = !key.empty() && key.size() <= kMaxLabelKeyChars && key[0] >= 'a' &&
                        key[0] <= 'z' && std::all_of(key.begin(), key.end(), [](char c) {
                          return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' ||
                                 c == '.' || c == '-';
                        });
    if (!key_ok) {
      return InvalidArgumentError("session.labels: key '" + key.substr(0, kMaxLabelKeyChars) +
                                  "' must be 1-" + std::to_string(kMaxLabelKeyChars) +
                                  " of [a-z0-9_.-] starting with a letter");
    }
    if (value.size() > kMaxLabelValueChars || std::any_of(value.begin(), value.end(), [](char c) {
          return static_cast<unsigned char>(c) < 0x20;
        })) {
      return InvalidArgumentError("session.labels['" + key + "']: the value must be at most " +
                                  std::to_string(kMaxLabelValueChars) +
                                  " characters with no control characters");
    }
  }
  return Status::Ok();
}

Status ValidatePipelineOptions(const v1::PipelineOptions& p) {
  if (!Finite(p.eps_h_px()) || p.eps_h_px() < 0 || p.eps_h_px() > kMaxEpsHPx) {
    return InvalidArgumentError("pipeline_options.eps_h_px must be in [0, 100] px (0 = default)");
  }
  if (!v1::PipelineOptions::ScaleSource_IsValid(p.scale_source())) {
    return InvalidArgumentError("pipeline_options.scale_source " +
                                std::to_string(p.scale_source()) + " is not one of " +
                                EnumValues(v1::PipelineOptions::ScaleSource_descriptor()));
  }
  if (p.refine_window_anchors() != 0 &&
      (p.refine_window_anchors() < 3 || p.refine_window_anchors() > 30)) {
    return InvalidArgumentError(
        "pipeline_options.refine_window_anchors must be in [3, 30] (0 = "
        "default), got " +
        std::to_string(p.refine_window_anchors()));
  }
  auto extension = [](bool has, double v, const char* name) {
    if (!has || (Finite(v) && v >= 0 && v <= kMaxBaselineExtensionS)) return Status::Ok();
    return InvalidArgumentError(std::string("pipeline_options.") + name + " must be in [0, " +
                                Num(kMaxBaselineExtensionS) + "] s (0 = off), got " + Num(v));
  };
  SLAPSE_RETURN_IF_ERROR(
      extension(p.has_init_max_baseline_s(), p.init_max_baseline_s(), "init_max_baseline_s"));
  SLAPSE_RETURN_IF_ERROR(
      extension(p.has_track_max_baseline_s(), p.track_max_baseline_s(), "track_max_baseline_s"));
  if (p.has_min_pair_span_s() && !(Finite(p.min_pair_span_s()) && p.min_pair_span_s() >= 0 &&
                                   p.min_pair_span_s() <= kMaxMinPairSpanS)) {
    return InvalidArgumentError("pipeline_options.min_pair_span_s must be in [0, " +
                                Num(kMaxMinPairSpanS) + "] s (0 = one pair per P frame), got " +
                                Num(p.min_pair_span_s()));
  }
  if (p.has_road_attitude_sigma_deg() &&
      !(Finite(p.road_attitude_sigma_deg()) && p.road_attitude_sigma_deg() >= 0 &&
        p.road_attitude_sigma_deg() <= kMaxRoadAttitudeSigmaDeg)) {
    return InvalidArgumentError("pipeline_options.road_attitude_sigma_deg must be in [0, " +
                                Num(kMaxRoadAttitudeSigmaDeg) + "] deg (0 = off), got " +
                                Num(p.road_attitude_sigma_deg()));
  }
  auto positive = [](double v) { return Finite(v) && v > 0; };
  switch (p.scale_source()) {
    case v1::PipelineOptions::FIRST_STEP:
      if (!positive(p.first_step_m())) {
        return InvalidArgumentError("pipeline_options.first_step_m must be > 0 for FIRST_STEP");
      }
      break;
    case v1::PipelineOptions::SPEED:
      if (!positive(p.speed_mps())) {
        return InvalidArgumentError("pipeline_options.speed_mps must be > 0 for SPEED");
      }
      break;
    case v1::PipelineOptions::CAMERA_HEIGHT:
      if (!positive(p.camera_height_m())) {
        return InvalidArgumentError(
            "pipeline_options.camera_height_m must be > 0 for CAMERA_HEIGHT");
      }
      break;
    default:
      break;
  }
  return Status::Ok();
}

Status ValidateListRequest(const v1::ListSessionsRequest& r) {
  if (r.page_size() < 0) {
    return InvalidArgumentError(
        "page_size must be >= 0 (0 = " + std::to_string(kDefaultListPageSize) + ")");
  }
  if (!v1::Session::State_IsValid(r.state_filter())) {
    return InvalidArgumentError("state_filter " + std::to_string(r.state_filter()) +
                                " is not one of " + EnumValues(v1::Session::State_descriptor()));
  }
  return Status::Ok();
}

Status ValidateIntrinsicsForImage(const v1::Intrinsics& k, int w, int h, const std::string& what) {
  const std::string size = std::to_string(w) + "x" + std::to_string(h);
  if (!(k.cx_px() >= 0 && k.cx_px() <= w && k.cy_px() >= 0 && k.cy_px() <= h)) {
    return InvalidArgumentError(what + ": the principal point (cx_px " + Num(k.cx_px()) +
                                ", cy_px " + Num(k.cy_px()) + ") is outside the " + size +
                                " image; want 0 <= cx_px <= " + std::to_string(w) +
                                " and 0 <= cy_px <= " + std::to_string(h));
  }
  SLAPSE_RETURN_IF_ERROR(
      CheckFov(what, "fx_px", k.fx_px(), "horizontal", w, kMinHorizontalFovDeg, kMaxFovDeg, size));
  return CheckFov(what, "fy_px", k.fy_px(), "vertical", h, kMinVerticalFovDeg, kMaxFovDeg, size);
}

}  // namespace slapse::api
