// The checks of a CreateSession request, shared by the server (which must
// refuse a bad request) and a client (which may check before it sends), and
// the defaults that a request's "0 = default" source fields stand for.
//
// Every check returns INVALID_ARGUMENT with a message that names the field
// and what it wants; the intrinsics go through core's ValidateIntrinsics.
#pragma once

#include <cstddef>
#include <string>

#include "core/common/status.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::api {

// Network sources (RtspPull / RtspPush / RtpSdp): start_timeout_ms and
// receive_timeout_ms when the request has 0, and the largest SDP accepted.
constexpr int kDefaultStartTimeoutMs = 60000;
constexpr int kDefaultReceiveTimeoutMs = 5000;
constexpr size_t kMaxSdpBytes = 64 << 10;
// RTSP pull: ReconnectPolicy defaults (0 in the request) and bounds.
constexpr int kDefaultReconnectIntervalMs = 1000;
constexpr double kDefaultBackoffMultiplier = 2.0;
constexpr int kDefaultMaxReconnectIntervalMs = 30000;
constexpr int kMaxReconnectAttempts = 1000000;
constexpr int kMaxReconnectIntervalMs = 3600000;
constexpr size_t kMaxRtspUrlChars = 2048;
// PipelineOptions.eps_h_px: the largest accepted, px.
constexpr double kMaxEpsHPx = 100.0;
// PipelineOptions.init_max_baseline_s and track_max_baseline_s: the longest
// accepted extension, s.
constexpr double kMaxBaselineExtensionS = 5.0;
// PipelineOptions.min_pair_span_s: the longest accepted chain, s.
constexpr double kMaxMinPairSpanS = 1.0;
// PipelineOptions.road_attitude_sigma_deg: the loosest accepted prior, deg.
constexpr double kMaxRoadAttitudeSigmaDeg = 10.0;

// The whole request: a source and its fields, the intrinsics and the
// pipeline options.
Status ValidateSession(const v1::Session& request);

// The parts.
Status ValidateSourceTimeouts(int start_timeout_ms, int receive_timeout_ms,
                              const std::string& what);
// rtsp:// or rtsps:// with a host (a name, an IPv4 address or a bracketed
// IPv6 address) and an optional port; no spaces or control characters.
Status ValidateRtspUrl(const std::string& url);
Status ValidateReconnectPolicy(const v1::ReconnectPolicy& policy);
// 1 to 256 of [A-Za-z0-9._-/], no leading '/'.
Status ValidateRtspPushPath(const std::string& path);
// A light syntax check (RFC 4566): "v=0" first, every line "<letter>=...",
// a c= line and an m=video line with a port.
Status ValidateSdp(const std::string& sdp);
// RtpSdp.allowed_senders: at most kMaxAllowedSenders IPv4 / IPv6 literals.
constexpr int kMaxAllowedSenders = 64;
Status ValidateAllowedSenders(const v1::RtpSdp& rtp);
Status ValidatePipelineOptions(const v1::PipelineOptions& options);
// Session.labels: at most kMaxLabels; keys 1 to kMaxLabelKeyChars of
// [a-z0-9_.-] starting with a letter; values at most kMaxLabelValueChars,
// no control characters.
constexpr size_t kMaxLabels = 64;
constexpr size_t kMaxLabelKeyChars = 63;
constexpr size_t kMaxLabelValueChars = 256;
Status ValidateLabels(const google::protobuf::Map<std::string, std::string>& labels);
// ListSessionsRequest: page_size >= 0 and state_filter one of Session.State.
Status ValidateListRequest(const v1::ListSessionsRequest& request);

// Intrinsics against the image they are for (the rule has this one home):
// the principal point inside the image (0 <= cx_px <= width_px,
// 0 <= cy_px <= height_px) and a plausible field of view: horizontal
// 2*atan(width_px / (2 fx_px)) in [10, 170] deg and vertical
// 2*atan(height_px / (2 fy_px)) in [5, 170] deg (a wide image's vertical
// field is narrower). `what` names the intrinsics and where the size came from.
constexpr double kMinHorizontalFovDeg = 10.0;
constexpr double kMinVerticalFovDeg = 5.0;
constexpr double kMaxFovDeg = 170.0;
Status ValidateIntrinsicsForImage(const v1::Intrinsics& k, int width_px, int height_px,
                                  const std::string& what);

// The one home of secret masking (responses, events, errors, logs).
//
// RedactUrl: the URL with any user:password@ replaced by ***@ and the value
// of every token-like query or fragment parameter (IsSecretParamName)
// replaced by ***:  rtsp://u:pw@cam/1?token=abc&ch=2 -> rtsp://***@cam/1?token=***&ch=2.
// Idempotent; a URL without '@' and without a secret parameter is unchanged.
// RedactUrl passes to a fixed point at most this many times; a text that
// needs more comes back as kRedactedUrl.
constexpr int kMaxRedactPasses = 64;
constexpr char kRedactedUrl[] = "<url redacted>";
std::string RedactUrl(const std::string& url);
// Whether a query parameter named `name` (any case) holds a secret: token,
// access_token, key, api_key, apikey, password, passwd, pwd, pass, secret,
// sig, signature, auth, authorization, credential(s), x-amz-signature, ...
// (also any name that ends in "token", "secret", "password" or "signature").
bool IsSecretParamName(const std::string& name);
// Free text (an error or log message): every URL in it (scheme://... up to a
// space or quote) through RedactUrl, the value of any secret name=value pair
// elsewhere (IsSecretParamName; up to a space, quote, & ; # or ,) and
// "Bearer <token>" -> "Bearer ***".
std::string RedactText(const std::string& text);
// A response or event as it may leave the server: URLs and messages masked
// (rtsp_pull.url, ingest_url, error, state_message; StateChange.message,
// Reconnecting.reason).
void RedactSession(v1::Session* session);
void RedactEvent(v1::SessionEvent* event);

}  // namespace slapse::api
