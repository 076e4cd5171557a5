// ListSessions' filter, order and pages (api/list_query.h) on hand-built
// sessions: each filter form matches what it says and nothing else; bad
// expressions are INVALID_ARGUMENT naming the column; pages cover the result
// exactly once and refuse a token from another query.
#include "api/list_query.h"

#include "api/validate.h"

#include <google/protobuf/util/time_util.h>
#include <gtest/gtest.h>

#include <set>
#include <string>
#include <vector>

namespace slapse::api {
namespace {

using google::protobuf::util::TimeUtil;

v1::Session MakeSession(const std::string& name, v1::Session::State state, const std::string& codec,
                        int64_t create_s, double lag_ms,
                        std::vector<std::pair<std::string, std::string>> labels) {
  v1::Session s;
  s.set_name(name);
  s.set_state(state);
  s.mutable_stream_report()->set_codec(codec);
  *s.mutable_create_time() = TimeUtil::SecondsToTimestamp(create_s);
  *s.mutable_update_time() = TimeUtil::SecondsToTimestamp(create_s + 10);
  s.mutable_stats()->set_lag_ms(lag_ms);
  s.mutable_stats()->set_frames(static_cast<int64_t>(lag_ms) * 2);
  for (auto& [k, v] : labels) (*s.mutable_labels())[k] = v;
  return s;
}

// 2026-11-23T10:00:00Z
constexpr int64_t kT0 = 1795428000;

std::vector<v1::Session> Fleet() {
  std::vector<v1::Session> f;
  f.push_back(MakeSession("sessions/a", v1::Session::RUNNING, "h264", kT0 + 0, 40,
                          {{"site", "depot"}, {"camera", "gate-1"}}));
  f.back().mutable_rtsp_pull()->set_url("rtsp://cam/1");
  f.push_back(MakeSession("sessions/b", v1::Session::FAILED, "mpeg2video", kT0 + 60, 900,
                          {{"site", "depot"}}));
  f.back().mutable_upload();
  f.push_back(MakeSession("sessions/c", v1::Session::RUNNING, "hevc", kT0 + 120, 700,
                          {{"site", "harbour"}, {"camera", "crane-2"}}));
  f.back().mutable_rtsp_push()->set_path("crane");
  f.push_back(MakeSession("sessions/d", v1::Session::FINISHED, "h264", kT0 + 180, 0, {}));
  f.back().mutable_rtp_sdp();
  return f;
}

// The names a filter keeps, in the default order.
std::vector<std::string> Names(const std::string& filter, const std::string& order_by = "") {
  v1::ListSessionsRequest r;
  r.set_filter(filter);
  r.set_order_by(order_by);
  auto page = ApplyListQuery(Fleet(), r);
  EXPECT_TRUE(page.ok()) << filter << ": " << page.status().ToString();
  std::vector<std::string> out;
  if (!page.ok()) return out;
  for (const auto& s : page->sessions()) out.push_back(s.name().substr(9));
  return out;
}

using V = std::vector<std::string>;

TEST(ListQuery, EmptyFilterKeepsAllInCreationOrder) {
  EXPECT_EQ(Names(""), (V{"a", "b", "c", "d"}));
  EXPECT_EQ(Names("   "), (V{"a", "b", "c", "d"}));
}

TEST(ListQuery, FieldsMatchWhatTheySay) {
  EXPECT_EQ(Names("state=RUNNING"), (V{"a", "c"}));
  EXPECT_EQ(Names("state!=RUNNING"), (V{"b", "d"}));
  EXPECT_EQ(Names("codec=h264"), (V{"a", "d"}));
  EXPECT_EQ(Names("codec=h26*"), (V{"a", "d"}));
  EXPECT_EQ(Names("codec=*video"), (V{"b"}));
  EXPECT_EQ(Names("codec=*ev*"), (V{"c"}));
  EXPECT_EQ(Names("source=rtsp_pull"), (V{"a"}));
  EXPECT_EQ(Names("source=upload OR source=rtp_sdp"), (V{"b", "d"}));
  EXPECT_EQ(Names("name=\"sessions/c\""), (V{"c"}));
  EXPECT_EQ(Names("labels.site=depot"), (V{"a", "b"}));
  EXPECT_EQ(Names("labels.site!=depot"), (V{"c", "d"}));  // unset counts as "not depot"
  EXPECT_EQ(Names("labels:camera"), (V{"a", "c"}));
  EXPECT_EQ(Names("labels.camera:*"), (V{"a", "c"}));
  EXPECT_EQ(Names("stats.lag_ms > 500"), (V{"b", "c"}));
  EXPECT_EQ(Names("stats.lag_ms <= 40"), (V{"a", "d"}));
  EXPECT_EQ(Names("stats.frames >= 1400"), (V{"b", "c"}));
  EXPECT_EQ(Names("stats.lag_ms > -1"), (V{"a", "b", "c", "d"}));
  EXPECT_EQ(Names("create_time >= \"2026-11-23T10:01:00Z\""), (V{"b", "c", "d"}));
  EXPECT_EQ(Names("create_time < \"2026-11-23T10:01:00Z\""), (V{"a"}));
  EXPECT_EQ(Names("update_time > \"2026-11-23T10:02:00Z\""), (V{"c", "d"}));
}

TEST(ListQuery, LogicFollowsAip160) {
  EXPECT_EQ(Names("state=RUNNING AND labels.site=depot"), (V{"a"}));
  EXPECT_EQ(Names("state=RUNNING labels.site=depot"), (V{"a"}));  // juxtaposition = AND
  // OR binds tighter than AND: a AND (b OR c).
  EXPECT_EQ(Names("labels.site=depot AND state=FAILED OR state=RUNNING"), (V{"a", "b"}));
  EXPECT_EQ(Names("(labels.site=depot AND state=FAILED) OR codec=hevc"), (V{"b", "c"}));
  EXPECT_EQ(Names("NOT state=RUNNING"), (V{"b", "d"}));
  EXPECT_EQ(Names("-state=RUNNING"), (V{"b", "d"}));
  EXPECT_EQ(Names("-(state=RUNNING OR state=FAILED)"), (V{"d"}));
  EXPECT_EQ(Names("NOT NOT codec=hevc"), (V{"c"}));
}

TEST(ListQuery, OrderBy) {
  EXPECT_EQ(Names("", "stats.lag_ms desc"), (V{"b", "c", "a", "d"}));
  EXPECT_EQ(Names("", "stats.lag_ms"), (V{"d", "a", "c", "b"}));
  EXPECT_EQ(Names("", "create_time desc"), (V{"d", "c", "b", "a"}));
  // Ties (same codec) fall back to creation order.
  EXPECT_EQ(Names("", "codec"), (V{"a", "d", "c", "b"}));
  EXPECT_EQ(Names("", "codec desc, name desc"), (V{"b", "c", "d", "a"}));
  // Without the label first, then by value.
  EXPECT_EQ(Names("", "labels.site"), (V{"d", "a", "b", "c"}));
  EXPECT_EQ(Names("", "state, name desc"), (V{"c", "a", "d", "b"}));
}

// The message names what is wrong and where.
void ExpectBad(const std::string& filter, const std::string& order_by, const std::string& words) {
  v1::ListSessionsRequest r;
  r.set_filter(filter);
  r.set_order_by(order_by);
  auto page = ApplyListQuery(Fleet(), r);
  ASSERT_FALSE(page.ok()) << "accepted filter '" << filter << "' order_by '" << order_by << "'";
  EXPECT_EQ(page.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(page.status().message().find(words), std::string::npos)
      << "'" << page.status().message() << "' lacks '" << words << "'";
}

TEST(ListQuery, BadExpressionsAreInvalidArgumentWithTheColumn) {
  ExpectBad("colour=red", "", "unknown field 'colour' at column 1");
  ExpectBad("state=RUNNIN", "", "unknown state 'RUNNIN'");
  ExpectBad("state>RUNNING", "", "use = or !=");
  ExpectBad("source=ftp", "", "unknown source 'ftp'");
  ExpectBad("codec<h264", "", "is text");
  ExpectBad("stats.lag_ms > soon", "", "is not a number");
  ExpectBad("stats.colour > 1", "", "unknown counter 'stats.colour'");
  ExpectBad("create_time > yesterday", "", "RFC 3339");
  ExpectBad("state=RUNNING AND", "", "at column 18");
  ExpectBad("(state=RUNNING", "", "expected ')' at column 15");
  ExpectBad("state=RUNNING)", "", "column 14");
  ExpectBad("state", "", "needs a comparison");
  ExpectBad("running", "", "needs a comparison");
  ExpectBad("codec=\"h264", "", "unterminated string");
  ExpectBad("state ! RUNNING", "", "'!' must be '!='");
  ExpectBad("state=RUNNING & codec=h264", "", "unexpected character '&' at column 15");
  ExpectBad(std::string(kMaxListQueryChars + 1, ' '), "", "longer than");
  ExpectBad(std::string(100, '(') + "state=RUNNING" + std::string(100, ')'), "", "nests deeper");
  ExpectBad("", "colour", "order_by: unknown field 'colour'");
  ExpectBad("", "name sideways", "want \"field\"");
  ExpectBad("", "name,,state", "order_by item 2 is empty");
}

TEST(ListQuery, PagesCoverTheResultOnceAndTokensAreBoundToTheQuery) {
  std::vector<v1::Session> many;
  for (int i = 0; i < 23; ++i) {
    many.push_back(MakeSession("sessions/s" + std::to_string(100 + i),
                               i % 3 == 0 ? v1::Session::FAILED : v1::Session::RUNNING, "h264",
                               kT0 + i, i, {}));
  }
  v1::ListSessionsRequest r;
  r.set_filter("state=RUNNING");
  r.set_order_by("stats.lag_ms desc");
  r.set_page_size(4);
  std::vector<std::string> seen;
  int pages = 0;
  do {
    auto page = ApplyListQuery(many, r);
    ASSERT_TRUE(page.ok()) << page.status().ToString();
    ASSERT_LE(page->sessions_size(), 4);
    for (const auto& s : page->sessions()) seen.push_back(s.name());
    r.set_page_token(page->next_page_token());
    ++pages;
  } while (!r.page_token().empty() && pages < 20);
  // 23 sessions, every third FAILED: 15 RUNNING, in lag order descending.
  ASSERT_EQ(seen.size(), 15u);
  EXPECT_EQ(pages, 4);
  EXPECT_EQ(std::set<std::string>(seen.begin(), seen.end()).size(), 15u);
  EXPECT_EQ(seen.front(), "sessions/s122");
  EXPECT_EQ(seen.back(), "sessions/s101");

  // A token from this query refused with another filter, and a made-up one.
  v1::ListSessionsRequest first = r;
  first.set_page_token("");
  auto page1 = ApplyListQuery(many, first);
  ASSERT_TRUE(page1.ok());
  v1::ListSessionsRequest other = first;
  other.set_filter("state=FAILED");
  other.set_page_token(page1->next_page_token());
  auto refused = ApplyListQuery(many, other);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("another filter"), std::string::npos);
  other.set_page_token("12");
  EXPECT_EQ(ApplyListQuery(many, other).status().code(), StatusCode::kInvalidArgument);
  // page_size beyond the cap is capped, negative refused.
  v1::ListSessionsRequest big;
  big.set_page_size(1 << 20);
  EXPECT_EQ(ApplyListQuery(many, big)->sessions_size(), 23);
  big.set_page_size(-1);
  EXPECT_FALSE(ApplyListQuery(many, big).ok());
}

TEST(ListQuery, LabelsAreValidated) {
  v1::Session s;
  (*s.mutable_labels())["site"] = "depot";
  (*s.mutable_labels())["camera.id"] = "gate-3";
  EXPECT_TRUE(ValidateLabels(s.labels()).ok());
  for (const std::string& bad :
       std::vector<std::string>{"", "Site", "1site", "si te", std::string(64, 'a')}) {
    v1::Session b;
    (*b.mutable_labels())[bad] = "x";
    EXPECT_EQ(ValidateLabels(b.labels()).code(), StatusCode::kInvalidArgument) << bad;
  }
  v1::Session long_value;
  (*long_value.mutable_labels())["site"] = std::string(kMaxLabelValueChars + 1, 'x');
  EXPECT_FALSE(ValidateLabels(long_value.labels()).ok());
  v1::Session too_many;
  for (size_t i = 0; i <= kMaxLabels; ++i) {
    (*too_many.mutable_labels())["k" + std::to_string(i)] = "v";
  }
  EXPECT_FALSE(ValidateLabels(too_many.labels()).ok());
}

}  // namespace
}  // namespace slapse::api
