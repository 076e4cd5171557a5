// The server's parts without a network: the session state machine (how a
// session ends), the worker pool, and how each ingest source reads the end
// of a connection (timeouts, end of stream, the RTSP pull reconnect policy).
// The same behaviour end to end is in server_test and rtsp_pull_test.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <optional>
#include <thread>
#include <vector>

#include "server/event_log.h"
#include "server/ingest_source.h"
#include "server/session.h"
#include "server/udp_ports.h"
#include "server/upload_queue.h"
#include "server/worker_pool.h"

namespace slapse::server {
namespace {

std::shared_ptr<Session> NewSession() {
  auto s = std::make_shared<Session>("sessions/1", 64, UploadQueueOptions{});
  s->Transition(v1::Session::CREATED, Status::Ok(), "created");
  return s;
}

std::vector<v1::SessionEvent> AllEvents(Session& s) {
  std::vector<v1::SessionEvent> out;
  bool ended = false;
  EXPECT_TRUE(s.events->Read(0, 1000, std::chrono::steady_clock::now(), &out, &ended).ok());
  return out;
}

TEST(SessionTest, EndStreamFinishesAtTheEndAndFailsOtherwise) {
  auto s = NewSession();
  s->EndStream(OutOfRangeError("eof"), "the stream ended");
  EXPECT_EQ(s->Snapshot().state(), v1::Session::FINISHED);
  const auto events = AllEvents(*s);
  ASSERT_EQ(events.size(), 2u);
  // No poses: the final message says why.
  EXPECT_EQ(events[1].state_change().message(),
            "the stream ended; no poses: no video frames were received");
  EXPECT_EQ(s->Snapshot().state_message(), events[1].state_change().message());

  s = NewSession();
  s->EndStream(UnavailableError("gone"), "unused");
  EXPECT_EQ(s->Snapshot().state(), v1::Session::FAILED);
  EXPECT_EQ(s->Snapshot().error().message(), "gone");
}

TEST(SessionTest, TheUploadsOwnErrorWinsAndStopWinsOverAll) {
  auto s = NewSession();
  s->ingest_error = ResourceExhaustedError("too big");
  s->EndStream(OutOfRangeError("eof"), "the stream ended");
  EXPECT_EQ(s->Snapshot().state(), v1::Session::FAILED);
  EXPECT_EQ(s->Snapshot().error().code(), static_cast<int>(StatusCode::kResourceExhausted));

  s = NewSession();
  s->stop = true;  // asked to stop, not yet marked
  s->End({v1::Session::FAILED, UnavailableError("x"), ""});
  EXPECT_EQ(s->Snapshot().state(), v1::Session::STOPPED);
  // Terminal states are final.
  s->Transition(v1::Session::RUNNING, Status::Ok());
  EXPECT_EQ(s->Snapshot().state(), v1::Session::STOPPED);
}

TEST(SessionTest, AFinishWithoutPosesSaysTheRunnersReason) {
  auto s = NewSession();
  s->no_pose_reason = "3 anchor pair(s) but none tracked; the last: no plane extracted";
  s->EndStream(OutOfRangeError("eof"), "the stream ended");
  EXPECT_EQ(s->Snapshot().state_message(),
            "the stream ended; no poses: 3 anchor pair(s) but none tracked; the last: no plane "
            "extracted");
  // With poses the message is the source's alone.
  s = NewSession();
  s->points = 1;
  s->EndStream(OutOfRangeError("eof"), "the stream ended");
  EXPECT_EQ(s->Snapshot().state_message(), "the stream ended");
}

// The reader gives up on an upload that never began or stalled; the reason
// names the serve flag. Bytes in time keep it alive.
TEST(UploadQueueTest, IdleTimeoutsCloseWithDeadlineExceeded) {
  UploadQueueOptions o;
  o.start_idle_timeout_ms = 50;
  o.stall_timeout_ms = 50;
  UploadQueue never(o);
  uint8_t buf[16];
  EXPECT_EQ(never.Read(buf, sizeof(buf)), -1);
  EXPECT_EQ(never.close_reason().code(), StatusCode::kDeadlineExceeded);
  EXPECT_NE(never.close_reason().message().find("no upload began within 0.05 s"), std::string::npos)
      << never.close_reason().message();
  EXPECT_EQ(never.Write("late", nullptr).code(), StatusCode::kDeadlineExceeded);

  UploadQueue stalled(o);
  stalled.Start();
  ASSERT_TRUE(stalled.Write("abcd", nullptr).ok());
  EXPECT_EQ(stalled.Read(buf, sizeof(buf)), 4);
  EXPECT_EQ(stalled.Read(buf, sizeof(buf)), -1);
  EXPECT_NE(
      stalled.close_reason().message().find("the upload stalled: no bytes arrived for 0.05 s"),
      std::string::npos)
      << stalled.close_reason().message();

  // No timeouts configured: a finished queue reads to its end.
  UploadQueue plain(UploadQueueOptions{});
  plain.Start();
  ASSERT_TRUE(plain.Write("ab", nullptr).ok());
  plain.Finish();
  EXPECT_EQ(plain.Read(buf, sizeof(buf)), 2);
  EXPECT_EQ(plain.Read(buf, sizeof(buf)), 0);
  EXPECT_TRUE(plain.close_reason().ok());
}

TEST(SessionTest, StopWakesAWait) {
  auto s = NewSession();
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    s->Stop("stopped by test");
  });
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(s->WaitForStop(10000));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
  stopper.join();
  EXPECT_EQ(s->Snapshot().state(), v1::Session::STOPPED);
}

TEST(WorkerPoolTest, RunsQueuedJobsBeforeShutdownReturns) {
  std::atomic<int> done{0};
  WorkerPool pool(2);
  for (int i = 0; i < 10; ++i) {
    pool.Submit([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      ++done;
    });
  }
  pool.Shutdown();
  EXPECT_EQ(done.load(), 10);
  pool.Shutdown();  // idempotent
}

TEST(IngestSourceTest, RtpSdpTimeoutsFailBeforeVideoAndFinishAfter) {
  v1::Session request;
  request.mutable_rtp_sdp()->set_start_timeout_ms(1500);
  auto source = IngestSource::Make(request, nullptr);
  EXPECT_TRUE(source->network());
  EXPECT_EQ(source->start_timeout_ms(), 1500);
  EXPECT_EQ(source->receive_timeout_ms(), 5000);  // 0 = the default

  auto s = NewSession();
  ConnectionEnd end;
  end.opened = true;
  end.timed_out = true;
  end.status = CancelledError("interrupted");
  EXPECT_FALSE(source->AfterConnection(s.get(), end).has_value());
  EXPECT_EQ(s->Snapshot().error().code(), static_cast<int>(StatusCode::kDeadlineExceeded));
  EXPECT_EQ(s->Snapshot().error().message(), "no RTP video arrived within start_timeout_ms=1500");

  s = NewSession();
  end.frames = end.session_frames = 30;
  EXPECT_FALSE(source->AfterConnection(s.get(), end).has_value());
  EXPECT_EQ(s->Snapshot().state(), v1::Session::FINISHED);
}

// A closed log with a store behind it holds no events in memory, and a
// watcher from any cursor still reads every event, then the end.
TEST(EventLogTest, ClosingReleasesTheRingAndReadsGoOnFromTheStore) {
  std::vector<v1::SessionEvent> store;  // what the store would hold, in order
  EventLog log(64);
  log.SetStore(
      [&](const std::vector<v1::SessionEvent>& e) {
        store.insert(store.end(), e.begin(), e.end());
      },
      [&](uint64_t after, size_t max, std::vector<v1::SessionEvent>* out) {
        for (const v1::SessionEvent& e : store) {
          if (e.sequence() > after && max > 0) {
            out->push_back(e);
            --max;
          }
        }
        return Status::Ok();
      });
  for (int i = 0; i < 100; ++i) log.Append(v1::SessionEvent());
  EXPECT_EQ(log.events_in_memory(), 64u);
  log.Close();
  EXPECT_EQ(log.events_in_memory(), 0u);
  EXPECT_EQ(log.last_sequence(), 100u);
  for (uint64_t cursor : {0, 40, 99}) {
    std::vector<v1::SessionEvent> got;
    bool ended = false;
    while (!ended) {
      ASSERT_TRUE(
          log.Read(cursor + got.size(), 30, std::chrono::steady_clock::now(), &got, &ended).ok());
    }
    ASSERT_EQ(got.size(), 100 - cursor);
    for (size_t i = 0; i < got.size(); ++i) EXPECT_EQ(got[i].sequence(), cursor + 1 + i);
  }
  // Without a store the ring is all there is: kept.
  EventLog alone(8);
  for (int i = 0; i < 5; ++i) alone.Append(v1::SessionEvent());
  alone.Close();
  EXPECT_EQ(alone.events_in_memory(), 5u);
}

TEST(UdpPortRangeTest, ParsesWholePairRangesAndNamesTheRuleBroken) {
  auto any = ParseUdpPortRange("any");
  ASSERT_TRUE(any.ok());
  EXPECT_TRUE(any->any());
  EXPECT_TRUE(any->Contains(5004));
  EXPECT_EQ(any->ToString(), "any");
  EXPECT_TRUE(ParseUdpPortRange("")->any());
  auto r = ParseUdpPortRange("40000-40099");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->min_port, 40000);
  EXPECT_EQ(r->max_port, 40099);
  EXPECT_TRUE(r->Contains(40000));
  EXPECT_TRUE(r->Contains(40099));
  EXPECT_FALSE(r->Contains(39999));
  EXPECT_FALSE(r->Contains(40100));
  EXPECT_EQ(ParseUdpPortRange(r->ToString())->max_port, 40099);  // round trip
  const std::pair<const char*, const char*> bad[] = {
      {"40000", "MIN-MAX"},         {"40000-", "MIN-MAX"},    {"-40099", "MIN-MAX"},
      {"4a000-40099", "digits"},    {"40000-70001", "65535"}, {"1000-1099", "1024"},
      {"40099-40000", "below MAX"}, {"40001-40099", "even"},  {"40000-40098", "even"},
      {"40000-4000000", "65535"}};
  for (const auto& [text, rule] : bad) {
    auto got = ParseUdpPortRange(text);
    ASSERT_FALSE(got.ok()) << text;
    EXPECT_EQ(got.status().code(), StatusCode::kInvalidArgument) << text;
    EXPECT_NE(got.status().message().find(rule), std::string::npos) << got.status().message();
  }
}

TEST(UdpPortRangeTest, AnSdpPortOutsideTheRangeIsInvalidAndNamesBoth) {
  const std::string sdp =
      "v=0\r\nc=IN IP4 127.0.0.1\r\nm=video 5004 RTP/AVP 96\r\na=rtpmap:96 H264/90000\r\n";
  EXPECT_TRUE(CheckRtpPortsInRange(sdp, UdpPortRange{}).ok());
  EXPECT_TRUE(CheckRtpPortsInRange(sdp, UdpPortRange{5004, 5005}).ok());
  const Status s = CheckRtpPortsInRange(sdp, UdpPortRange{40000, 40099});
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("5004"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("40000-40099"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("--rtp-ports"), std::string::npos) << s.message();
  // the RTCP port (RTP + 1) must be in the range too
  EXPECT_EQ(CheckRtpPortsInRange(sdp, UdpPortRange{5002, 5004}).code(),
            StatusCode::kInvalidArgument);
}

TEST(IngestSourceTest, RtspPushEndsWithThePublisher) {
  v1::Session request;
  request.mutable_rtsp_push()->set_path("cam");
  auto source = IngestSource::Make(request, nullptr);
  auto s = NewSession();
  ConnectionEnd end;
  end.opened = true;
  end.status = OutOfRangeError("eof");
  end.frames = end.session_frames = 10;
  s->points = 1;  // it had poses (else the message says why not)
  EXPECT_FALSE(source->AfterConnection(s.get(), end).has_value());
  EXPECT_EQ(s->Snapshot().state(), v1::Session::FINISHED);
  const auto events = AllEvents(*s);
  EXPECT_EQ(events.back().state_change().message(), "the publisher ended the stream (TEARDOWN)");
}

TEST(IngestSourceTest, UploadHasNoDeadline) {
  v1::Session request;
  request.mutable_upload();
  EXPECT_FALSE(IngestSource::Make(request, nullptr)->network());
}

TEST(IngestSourceTest, RtspPullBacksOffThenGivesUp) {
  v1::Session request;
  request.mutable_rtsp_pull()->set_url("rtsp://user:pw@cam:554/1");
  v1::ReconnectPolicy* p = request.mutable_rtsp_pull()->mutable_reconnect();
  p->set_max_attempts(3);
  p->set_initial_interval_ms(100);
  p->set_max_interval_ms(250);
  auto source = IngestSource::Make(request, nullptr);
  auto s = NewSession();
  ConnectionEnd refused;
  // As Open reports it (credentials already dropped).
  refused.status = UnavailableError("cannot open 'rtsp://***@cam:554/1': refused");
  // 100, 200, then capped at 250 ms.
  EXPECT_EQ(source->AfterConnection(s.get(), refused), std::optional<int>(100));
  EXPECT_EQ(source->AfterConnection(s.get(), refused), std::optional<int>(200));
  // Frames flowing end the outage: the next one (a lost camera: the
  // connection closed and no longer answers) starts again at 100 ms.
  ConnectionEnd ended;
  ended.opened = true;
  ended.status = UnavailableError("the connection was lost after 40 packets");
  ended.frames = 5;
  EXPECT_EQ(source->AfterConnection(s.get(), ended), std::optional<int>(100));
  EXPECT_EQ(source->AfterConnection(s.get(), refused), std::optional<int>(200));
  EXPECT_EQ(source->AfterConnection(s.get(), refused), std::optional<int>(250));
  EXPECT_EQ(s->Snapshot().stats().reconnects(), 5);
  EXPECT_FALSE(source->AfterConnection(s.get(), refused).has_value());
  const v1::Session snap = s->Snapshot();
  EXPECT_EQ(snap.state(), v1::Session::FAILED);
  EXPECT_EQ(snap.error().code(), static_cast<int>(StatusCode::kUnavailable));
  EXPECT_EQ(snap.error().message().find("pw"), std::string::npos) << snap.error().message();
  EXPECT_NE(snap.error().message().find("gave up after 3 reconnect attempt(s)"), std::string::npos)
      << snap.error().message();
  int reconnecting = 0;
  for (const auto& e : AllEvents(*s)) reconnecting += e.has_reconnecting();
  EXPECT_EQ(reconnecting, 5);
}

TEST(IngestSourceTest, RtspPullWithoutReconnectFinishesAStreamThatEnded) {
  v1::Session request;
  request.mutable_rtsp_pull()->set_url("rtsp://cam/1");
  auto source = IngestSource::Make(request, nullptr);
  auto s = NewSession();
  ConnectionEnd ended;
  ended.opened = true;
  ended.status = OutOfRangeError("eof");
  ended.frames = 5;
  EXPECT_FALSE(source->AfterConnection(s.get(), ended).has_value());
  EXPECT_EQ(s->Snapshot().state(), v1::Session::FINISHED);
}

}  // namespace
}  // namespace slapse::server
