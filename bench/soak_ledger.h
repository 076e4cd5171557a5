// A watcher's account of the events it was delivered (bench/soak.cc): every
// SessionEvent.sequence it saw, across drops and resumes, checked at the end
// against the session's 1..last_sequence. Lost = an expected sequence never
// delivered; repeated = a delivery beyond the first of a sequence; unexpected
// = a sequence outside 1..last_sequence.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

namespace slapse::bench {

struct LedgerTally {
  uint64_t expected = 0;    // last_sequence: events 1..expected
  uint64_t delivered = 0;   // deliveries, repeats included
  uint64_t lost = 0;        // expected sequences never delivered
  uint64_t repeated = 0;    // deliveries of a sequence already delivered
  uint64_t unexpected = 0;  // deliveries of 0 or of a sequence > expected
};

class SequenceLedger {
 public:
  void Deliver(uint64_t sequence) {
    ++delivered_;
    if (sequence >= counts_.size()) counts_.resize(sequence + 1, 0);
    ++counts_[sequence];
    cursor_ = std::max(cursor_, sequence);
  }
  // The sequence to resume a watch after: the highest delivered (0: none).
  uint64_t cursor() const { return cursor_; }
  uint64_t delivered() const { return delivered_; }

  LedgerTally Against(uint64_t last_sequence) const {
    LedgerTally t;
    t.expected = last_sequence;
    t.delivered = delivered_;
    for (uint64_t s = 0; s < counts_.size(); ++s) {
      const uint32_t c = counts_[s];
      if (s == 0 || s > last_sequence) {
        t.unexpected += c;
        continue;
      }
      if (c > 1) t.repeated += c - 1;
    }
    for (uint64_t s = 1; s <= last_sequence; ++s) {
      if (s >= counts_.size() || counts_[s] == 0) ++t.lost;
    }
    return t;
  }

 private:
  std::vector<uint32_t> counts_;  // deliveries per sequence
  uint64_t delivered_ = 0;
  uint64_t cursor_ = 0;
};

}  // namespace slapse::bench
