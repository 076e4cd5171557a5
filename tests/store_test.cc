// The server's store (server/store.h) on a real SQLite database in a temp
// directory: what a step commits is there after reopening, a rescale replaces
// only its own segment's points, pages and time ranges, the data directory's
// lock and errors; and a session's event log reading beyond its ring from
// the store.
#include "server/store.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "server/session.h"
#include "tests/test_streams.h"

namespace slapse::server {
namespace {

v1::Trajectory::Point Point(int64_t anchor, double t_s, int segment) {
  v1::Trajectory::Point p;
  p.set_anchor_index(anchor);
  p.set_timestamp_s(t_s);
  p.mutable_world_from_cam()->set_tx(0.5 * static_cast<double>(anchor));
  p.mutable_world_from_cam()->set_qw(1.0);
  p.set_segment(segment);
  return p;
}

v1::SessionEvent PoseEvent(uint64_t seq, int64_t anchor) {
  v1::SessionEvent e;
  e.set_sequence(seq);
  e.mutable_pose()->set_sequence(seq);
  e.mutable_pose()->set_anchor_index(anchor);
  return e;
}

v1::Session NewRow(const std::string& name) {
  v1::Session s;
  s.set_name(name);
  s.set_state(v1::Session::RUNNING);
  s.mutable_upload();
  s.mutable_intrinsics()->set_fx_px(500);
  return s;
}

class StoreTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = testing::MakeTempDir("store_test"); }
  std::unique_ptr<Store> OpenOrDie() {
    auto store = Store::Open(dir_);
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    return store.ok() ? std::move(*store) : nullptr;
  }
  std::string dir_;
};

TEST_F(StoreTest, ACommittedStepIsThereAfterReopening) {
  int64_t ordinal = 0;
  {
    auto store = OpenOrDie();
    ASSERT_NE(store, nullptr);
    auto added = store->AddSession(NewRow("sessions/abc"));
    ASSERT_TRUE(added.ok()) << added.status().ToString();
    ordinal = *added;
    v1::Session row = NewRow("sessions/abc");
    row.mutable_stats()->set_frames(42);
    StoreStep step;
    step.session = &row;
    step.metric = true;
    for (int i = 0; i < 3; ++i) step.points.push_back(Point(2 * i, 0.1 * i, 0));
    v1::PlaneMap::Plane plane;
    plane.set_track_id(7);
    plane.set_distance(1.5);
    step.planes.push_back(plane);
    ASSERT_TRUE(store->Commit(ordinal, step, {PoseEvent(1, 4), PoseEvent(2, 4)}).ok());
  }  // closed like a process that ends (WAL checkpoint or not)
  auto store = OpenOrDie();
  ASSERT_NE(store, nullptr);
  auto loaded = store->LoadSessions();
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  ASSERT_EQ(loaded->size(), 1u);
  const StoredSession& s = (*loaded)[0];
  EXPECT_EQ(s.ordinal, ordinal);
  EXPECT_EQ(s.proto.name(), "sessions/abc");
  EXPECT_EQ(s.proto.stats().frames(), 42);
  EXPECT_EQ(s.proto.intrinsics().fx_px(), 500);  // the whole proto persists
  EXPECT_TRUE(s.metric);
  EXPECT_EQ(s.last_sequence, 2u);
  EXPECT_EQ(s.points, 3);
  EXPECT_EQ(s.max_segment, 0);
  EXPECT_EQ(s.max_anchor_index, 4);
  std::vector<v1::SessionEvent> events;
  ASSERT_TRUE(store->ReadEvents(ordinal, 1, 10, &events).ok());
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].sequence(), 2u);
  std::vector<v1::PlaneMap::Plane> planes;
  int64_t key = -1;
  ASSERT_TRUE(store->ReadPlanes(ordinal, -1, 10, &planes, &key).ok());
  ASSERT_EQ(planes.size(), 1u);
  EXPECT_EQ(planes[0].distance(), 1.5);
}

TEST_F(StoreTest, ARescaleReplacesOnlyItsOwnSegment) {
  auto store = OpenOrDie();
  ASSERT_NE(store, nullptr);
  auto ordinal = store->AddSession(NewRow("sessions/seg"));
  ASSERT_TRUE(ordinal.ok());
  StoreStep first;
  first.segment = 0;
  for (int i = 0; i < 4; ++i) first.points.push_back(Point(i, i, 0));
  ASSERT_TRUE(store->Commit(*ordinal, first, {}).ok());
  StoreStep second;  // resumed after a restart: segment 1
  second.segment = 1;
  for (int i = 10; i < 13; ++i) second.points.push_back(Point(i, i, 1));
  ASSERT_TRUE(store->Commit(*ordinal, second, {}).ok());
  StoreStep rescale;  // segment 1's pipeline fixed its scale: all of its points anew
  rescale.segment = 1;
  rescale.replace_points = true;
  for (int i = 10; i < 14; ++i) rescale.points.push_back(Point(i, i, 1));
  ASSERT_TRUE(store->Commit(*ordinal, rescale, {}).ok());
  std::vector<v1::Trajectory::Point> points;
  std::vector<int64_t> numbers;
  ASSERT_TRUE(store->ReadPoints(*ordinal, 0, -1e300, 0, 100, &points, &numbers).ok());
  ASSERT_EQ(points.size(), 8u);  // 4 of segment 0 kept, 4 of segment 1
  for (int i = 0; i < 4; ++i) EXPECT_EQ(points[i].segment(), 0);
  for (int i = 4; i < 8; ++i) EXPECT_EQ(points[i].anchor_index(), 6 + i);
  EXPECT_EQ(store->CountPoints(*ordinal), 8);
}

TEST_F(StoreTest, PagesAndTimeRangesCoverThePointsOnce) {
  auto store = OpenOrDie();
  ASSERT_NE(store, nullptr);
  auto ordinal = store->AddSession(NewRow("sessions/pages"));
  ASSERT_TRUE(ordinal.ok());
  for (int step = 0; step < 25; ++step) {
    StoreStep s;
    s.points.push_back(Point(step, 0.5 * step, 0));
    ASSERT_TRUE(store->Commit(*ordinal, s, {}).ok());
  }
  std::vector<int64_t> seen;
  int64_t after = 0;
  for (int page = 0; page < 10; ++page) {
    std::vector<v1::Trajectory::Point> points;
    std::vector<int64_t> numbers;
    ASSERT_TRUE(store->ReadPoints(*ordinal, after, -1e300, 0, 7, &points, &numbers).ok());
    if (points.empty()) break;
    for (const auto& p : points) seen.push_back(p.anchor_index());
    after = numbers.back();
  }
  ASSERT_EQ(seen.size(), 25u);
  for (int i = 0; i < 25; ++i) EXPECT_EQ(seen[i], i);
  // [2.0 s, 4.0 s): anchors 4..7.
  std::vector<v1::Trajectory::Point> range;
  std::vector<int64_t> numbers;
  ASSERT_TRUE(store->ReadPoints(*ordinal, 0, 2.0, 4.0, 100, &range, &numbers).ok());
  ASSERT_EQ(range.size(), 4u);
  EXPECT_EQ(range.front().anchor_index(), 4);
  EXPECT_EQ(range.back().anchor_index(), 7);
}

TEST_F(StoreTest, DeleteAndExpireDropTheResults) {
  auto store = OpenOrDie();
  ASSERT_NE(store, nullptr);
  auto a = store->AddSession(NewRow("sessions/a"));
  auto b = store->AddSession(NewRow("sessions/b"));
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_GT(*b, *a);  // creation order
  StoreStep s;
  s.points.push_back(Point(1, 1, 0));
  ASSERT_TRUE(store->Commit(*a, s, {PoseEvent(1, 1), PoseEvent(2, 1)}).ok());
  ASSERT_TRUE(store->Commit(*b, s, {PoseEvent(1, 1), PoseEvent(2, 1), PoseEvent(3, 1)}).ok());
  ASSERT_TRUE(store->DeleteSession(*a).ok());
  v1::Session expired = NewRow("sessions/b");
  expired.set_state(v1::Session::EXPIRED);
  ASSERT_TRUE(store->ExpireResults(*b, expired, 3).ok());
  auto loaded = store->LoadSessions();
  ASSERT_TRUE(loaded.ok());
  ASSERT_EQ(loaded->size(), 1u);
  EXPECT_EQ((*loaded)[0].proto.state(), v1::Session::EXPIRED);
  EXPECT_EQ((*loaded)[0].points, 0);
  std::vector<v1::SessionEvent> events;
  ASSERT_TRUE(store->ReadEvents(*b, 0, 10, &events).ok());
  ASSERT_EQ(events.size(), 1u);  // only the kept one (the expiry event)
  EXPECT_EQ(events[0].sequence(), 3u);
  // A deleted session's ordinal is not handed out again.
  auto c = store->AddSession(NewRow("sessions/c"));
  ASSERT_TRUE(c.ok());
  EXPECT_GT(*c, *b);
}

// The bytes of `dir`'s database files on disk (the database and its WAL).
int64_t FileBytes(const std::string& dir) {
  int64_t bytes = 0;
  for (const char* name : {"/slapse.db", "/slapse.db-wal"}) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(dir + name, ec);
    if (!ec) bytes += static_cast<int64_t>(size);
  }
  return bytes;
}

// Store::SizeBytes (the metric's and the retention budget's measure) grows
// with a session's results and falls as soon as they are expired; Reclaim
// gives the freed pages back to the file system (a new store is
// auto_vacuum=INCREMENTAL) and truncates the WAL.
TEST_F(StoreTest, SizeFollowsTheDataAndReclaimShrinksTheFile) {
  auto store = OpenOrDie();
  ASSERT_NE(store, nullptr);
  const int64_t empty = store->SizeBytes();
  EXPECT_GT(empty, 0);  // the schema's pages
  auto a = store->AddSession(NewRow("sessions/a"));
  auto b = store->AddSession(NewRow("sessions/b"));
  ASSERT_TRUE(a.ok() && b.ok());
  // 2000 points and events each: about 0.7 MB per session.
  for (const int64_t ordinal : {*a, *b}) {
    for (int step = 0; step < 20; ++step) {
      StoreStep s;
      std::vector<v1::SessionEvent> events;
      for (int i = 0; i < 100; ++i) {
        const int64_t n = step * 100 + i;
        s.points.push_back(Point(n, 0.1 * static_cast<double>(n), 0));
        v1::SessionEvent e;
        e.set_sequence(static_cast<uint64_t>(n + 1));
        e.mutable_state_change()->set_message(std::string(300, 'm'));
        events.push_back(e);
      }
      ASSERT_TRUE(store->Commit(ordinal, s, events).ok());
    }
  }
  const int64_t full = store->SizeBytes();
  EXPECT_GT(full - empty, 2 * 400000) << "two sessions' rows";
  ASSERT_TRUE(store->Reclaim().ok());
  const int64_t file_full = FileBytes(dir_);
  EXPECT_GE(file_full, full);

  v1::Session expired = NewRow("sessions/a");
  expired.set_state(v1::Session::EXPIRED);
  ASSERT_TRUE(store->ExpireResults(*a, expired, 2000).ok());
  const int64_t half = store->SizeBytes();
  // About half went at once (session b's rows stay).
  EXPECT_LT(half, full - (full - empty) / 3) << empty << " " << full;
  EXPECT_GT(half, empty + (full - empty) / 3);
  ASSERT_TRUE(store->Reclaim().ok());
  const int64_t file_half = FileBytes(dir_);
  EXPECT_LT(file_half, file_full - (full - half) / 2) << "the file shrank";
  EXPECT_EQ(store->SizeBytes(), half);

  // In memory: the same measure.
  auto memory = Store::Open(kInMemoryDataDir);
  ASSERT_TRUE(memory.ok());
  EXPECT_GT((*memory)->SizeBytes(), 0);
}

TEST_F(StoreTest, OneServerPerDataDirectory) {
  auto first = OpenOrDie();
  ASSERT_NE(first, nullptr);
  auto second = Store::Open(dir_);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(second.status().message().find("in use by another slapse server"), std::string::npos)
      << second.status().message();
  first.reset();  // released with the store (and by the kernel if the process dies)
  EXPECT_NE(OpenOrDie(), nullptr);
}

TEST_F(StoreTest, AnUnusableDataDirectoryIsAPreciseError) {
  const std::string file = dir_ + "/not_a_dir";
  std::ofstream(file) << "x";
  auto store = Store::Open(file + "/data");
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(store.status().message().find("cannot create the data directory"), std::string::npos)
      << store.status().message();
  std::filesystem::create_directories(dir_ + "/junk");
  std::ofstream(dir_ + "/junk/slapse.db", std::ios::binary) << std::string(4096, 'j');
  auto junk = Store::Open(dir_ + "/junk");
  ASSERT_FALSE(junk.ok());
  EXPECT_EQ(junk.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(junk.status().message().find("not usable"), std::string::npos)
      << junk.status().message();
}

// A session's event log with a ring of 4 in front of the store: a watcher
// from sequence 0 gets every event, from the store and then from the ring.
TEST_F(StoreTest, AWatcherReadsBeyondTheRingFromTheStore) {
  std::shared_ptr<Store> store = OpenOrDie();
  ASSERT_NE(store, nullptr);
  auto ordinal = store->AddSession(NewRow("sessions/ring"));
  ASSERT_TRUE(ordinal.ok());
  Session s("sessions/ring", /*ring=*/4, UploadQueueOptions{}, store, *ordinal);
  for (int i = 0; i < 20; ++i) s.events->Append(PoseEvent(0, i));
  std::vector<v1::SessionEvent> all;
  bool ended = false;
  for (int reads = 0; reads < 50 && all.size() < 20; ++reads) {
    const uint64_t cursor = all.empty() ? 0 : all.back().sequence();
    ASSERT_TRUE(s.events->Read(cursor, 6, std::chrono::steady_clock::now(), &all, &ended).ok());
  }
  ASSERT_EQ(all.size(), 20u);
  for (size_t i = 0; i < all.size(); ++i) {
    EXPECT_EQ(all[i].sequence(), i + 1);
    EXPECT_EQ(all[i].pose().anchor_index(), static_cast<int64_t>(i));
  }
  // Without a store behind it, the same cursor is OUT_OF_RANGE.
  Session bare("sessions/bare", 4, UploadQueueOptions{});
  for (int i = 0; i < 20; ++i) bare.events->Append(PoseEvent(0, i));
  std::vector<v1::SessionEvent> none;
  EXPECT_EQ(bare.events->Read(0, 6, std::chrono::steady_clock::now(), &none, &ended).code(),
            StatusCode::kOutOfRange);
}

}  // namespace
}  // namespace slapse::server
