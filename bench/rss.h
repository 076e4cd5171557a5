// Resident set sizes for the benches (timing and memory live in bench/,
// never in tests): this process's, or another's by pid (the soak's
// `slapse serve`).
#pragma once

#include <sys/types.h>

#include <cstdlib>
#include <fstream>
#include <string>

namespace slapse::bench {

// VmRSS from a /proc/<pid>/status file, KiB; -1 if it cannot be read.
inline long RssKbFromStatus(const std::string& status_path) {
  std::ifstream in(status_path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atol(line.c_str() + 6);
  }
  return -1;
}

// This process's VmRSS, KiB; -1 if it cannot be read.
inline long RssKb() { return RssKbFromStatus("/proc/self/status"); }

// Process `pid`'s VmRSS, KiB; -1 if it cannot be read (e.g. it has exited).
inline long RssKbOf(pid_t pid) {
  return RssKbFromStatus("/proc/" + std::to_string(pid) + "/status");
}

}  // namespace slapse::bench
