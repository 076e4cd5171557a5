// The soak's pure accounting (bench/soak_ledger.h, bench/stats.h): lost,
// repeated and unexpected events from a watcher's sequence numbers, the resume
// cursor, percentiles and the RSS slope.
#include <gtest/gtest.h>

#include "bench/soak_ledger.h"
#include "bench/stats.h"

namespace slapse::bench {
namespace {

TEST(SequenceLedgerTest, EveryEventOnceIsClean) {
  SequenceLedger l;
  for (uint64_t s = 1; s <= 5; ++s) l.Deliver(s);
  const LedgerTally t = l.Against(5);
  EXPECT_EQ(t.expected, 5u);
  EXPECT_EQ(t.delivered, 5u);
  EXPECT_EQ(t.lost, 0u);
  EXPECT_EQ(t.repeated, 0u);
  EXPECT_EQ(t.unexpected, 0u);
  EXPECT_EQ(l.cursor(), 5u);
}

TEST(SequenceLedgerTest, GapsAreLostRepeatsAreCountedPerExtraDelivery) {
  SequenceLedger l;
  for (uint64_t s : {1, 2, 2, 4, 2, 5}) l.Deliver(s);  // 3 and 6 never came
  const LedgerTally t = l.Against(6);
  EXPECT_EQ(t.delivered, 6u);
  EXPECT_EQ(t.lost, 2u);
  EXPECT_EQ(t.repeated, 2u);
  EXPECT_EQ(t.unexpected, 0u);
}

TEST(SequenceLedgerTest, ResumeCursorIsTheHighestSeenAndNothingSeenIsZero) {
  SequenceLedger l;
  EXPECT_EQ(l.cursor(), 0u);
  EXPECT_EQ(l.Against(3).lost, 3u);  // a watcher that saw nothing lost everything
  l.Deliver(3);
  l.Deliver(1);  // late, out of order
  EXPECT_EQ(l.cursor(), 3u);
  EXPECT_EQ(l.Against(3).lost, 1u);
}

TEST(SequenceLedgerTest, ZeroAndBeyondTheLastAreUnexpected) {
  SequenceLedger l;
  for (uint64_t s : {0, 1, 2, 9}) l.Deliver(s);
  const LedgerTally t = l.Against(2);
  EXPECT_EQ(t.unexpected, 2u);
  EXPECT_EQ(t.lost, 0u);
  EXPECT_EQ(t.repeated, 0u);
}

TEST(StatsTest, PercentileIsNearestRank) {
  EXPECT_EQ(Percentile({}, 0.5), 0);
  EXPECT_EQ(Percentile({3, 1, 2}, 0.5), 2);
  EXPECT_EQ(Percentile({5, 1, 4, 2, 3}, 0.0), 1);
  EXPECT_EQ(Percentile({5, 1, 4, 2, 3}, 1.0), 5);
  std::vector<double> v;
  for (int i = 1; i <= 100; ++i) v.push_back(i);
  EXPECT_EQ(Percentile(v, 0.99), 99);
}

TEST(StatsTest, LeastSquaresSlope) {
  EXPECT_DOUBLE_EQ(LeastSquaresSlope({0, 1, 2, 3}, {10, 12, 14, 16}), 2.0);
  EXPECT_DOUBLE_EQ(LeastSquaresSlope({0, 1, 2, 3}, {5, 5, 5, 5}), 0.0);
  EXPECT_DOUBLE_EQ(LeastSquaresSlope({0, 1, 2, 3}, {1, 0, 1, 0}), -0.2);
  EXPECT_EQ(LeastSquaresSlope({1}, {1}), 0);
  EXPECT_EQ(LeastSquaresSlope({2, 2}, {1, 3}), 0);
}

}  // namespace
}  // namespace slapse::bench
