// ListSessions' query: the filter (an AIP-160 subset), the order (AIP-132
// order_by) and the page, applied to the caller's sessions. One home for the
// grammar, shared by the server (which answers the query) and the CLI (which
// checks a filter before it sends one).
//
// Filter grammar (AIP-160; OR binds tighter than AND, as AIP-160 says):
//   expression := sequence { "AND" sequence }
//   sequence   := factor { factor }                  (juxtaposition = AND)
//   factor     := term { "OR" term }
//   term       := [ "NOT" | "-" ] simple
//   simple     := "(" expression ")" | field comparator value | "labels" ":" key
//   comparator := "=" | "!=" | "<" | "<=" | ">" | ">=" | ":"
// Fields and what they take:
//   name, codec                   text (codec: Session.stream_report.codec, the
//                                 stream's own codec, also when re-encoded);
//                                 "=", "!=", ":" with an optional '*' at
//                                 either end as a wildcard ("h26*")
//   state                         a Session.State name: "=", "!="
//   source                        upload | rtsp_pull | rtsp_push | rtp_sdp: "=", "!="
//   create_time, update_time      a quoted RFC 3339 time ("2026-11-23T10:00:00Z"):
//                                 all six comparisons
//   stats.<counter>               a number: all six comparisons; counters are
//                                 SessionStats' fields (frames, fps, lag_ms, ...)
//   labels.<key>                  text as for name; "labels.<key>:*" and
//                                 "labels:<key>" test that the label is set
// Values are bare words ([A-Za-z0-9_.*+-]) or double-quoted strings with \"
// and \\ escapes. A malformed expression, an unknown field or a value of the
// wrong kind is INVALID_ARGUMENT naming the column (1-based) and what was
// expected.
//
// order_by: "field [asc|desc]" separated by commas, fields name, state,
// source, codec, create_time, update_time, stats.<counter>, labels.<key>;
// ties keep the server's creation order. Empty = creation order.
//
// Pages are positions in the filtered, ordered result; next_page_token is
// opaque and only valid with the same filter and order_by. A session created,
// deleted or reordered between two pages may move across the boundary
// (appear twice or not at all); with the default order, sessions created
// later only ever append.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "slapse/v1/slapse.pb.h"

namespace slapse::api {

// Longest filter / order_by accepted, characters, and deepest nesting.
constexpr size_t kMaxListQueryChars = 2048;
constexpr int kMaxFilterDepth = 32;
// ListSessionsRequest.page_size: 0 means kDefaultListPageSize; larger than
// kMaxListPageSize is capped.
constexpr int kDefaultListPageSize = 50;
constexpr int kMaxListPageSize = 1000;

class SessionFilter {
 public:
  // Matches every session.
  SessionFilter();
  // Parses `expression` (empty = match all).
  static StatusOr<SessionFilter> Parse(const std::string& expression);
  bool Matches(const v1::Session& session) const;

  struct Node;  // the parsed expression (list_query.cc)

 private:
  std::shared_ptr<const Node> root_;  // null = match all
};

class SessionOrder {
 public:
  // The default order: none (the caller's order, which is creation order).
  SessionOrder();
  static StatusOr<SessionOrder> Parse(const std::string& order_by);
  // Strict weak order: true if `a` comes before `b`.
  bool Less(const v1::Session& a, const v1::Session& b) const;

  struct Key;  // one "field [asc|desc]" (list_query.cc)

 private:
  std::vector<std::shared_ptr<const Key>> keys_;
};

// Filters `sessions` (every session the caller may see, in creation order)
// by request.filter and request.state_filter, orders them stably by
// request.order_by and returns the page that request.page_token / page_size
// ask for.
// INVALID_ARGUMENT for a bad filter, order_by, page size or token.
StatusOr<v1::ListSessionsResponse> ApplyListQuery(std::vector<v1::Session> sessions,
                                                  const v1::ListSessionsRequest& request);

}  // namespace slapse::api
