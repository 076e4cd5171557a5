// This process's resident set size, for the benches (timing and memory live
// in bench/, never in tests).
#pragma once

#include <cstdlib>
#include <fstream>
#include <string>

namespace slapse::bench {

// VmRSS from /proc/self/status, KiB; -1 if it cannot be read.
inline long RssKb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atol(line.c_str() + 6);
  }
  return -1;
}

}  // namespace slapse::bench
