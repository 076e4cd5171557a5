// Wall-clock helpers for the per-stage timings (steady clock).
#pragma once

#include <chrono>

namespace slapse {

using SteadyClock = std::chrono::steady_clock;

// Seconds from `a` to `b`.
inline double SecondsBetween(SteadyClock::time_point a, SteadyClock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// Milliseconds from `t0` to now.
inline double MsSince(SteadyClock::time_point t0) {
  return std::chrono::duration<double, std::milli>(SteadyClock::now() - t0).count();
}

}  // namespace slapse
