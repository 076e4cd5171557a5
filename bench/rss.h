// Resident set sizes for the benches (timing and memory live in bench/,
// never in tests): this process's, or another's by pid (the soak's
// `slapse serve`).
#pragma once

#include <sys/types.h>

#include <cstdlib>
#include <fstream>
#include <string>

namespace slapse::bench {

// A "<key>: <n> kB" field of a /proc/<pid>/status file, KiB; -1 if it cannot
// be read (e.g. the process has exited).
inline long StatusKb(const std::string& status_path, const std::string& key) {
  std::ifstream in(status_path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key + ":", 0) == 0) return std::atol(line.c_str() + key.size() + 1);
  }
  return -1;
}

// VmRSS: all resident pages, shared libraries' included; this process's.
inline long RssKb() { return StatusKb("/proc/self/status", "VmRSS"); }
// RssAnon: the resident pages no file backs (heap, arenas, stacks).
inline long RssAnonKb() { return StatusKb("/proc/self/status", "RssAnon"); }
// Process `pid`'s VmRSS, KiB; -1 if it cannot be read (e.g. it has exited).
inline long RssKbOf(pid_t pid) {
  return StatusKb("/proc/" + std::to_string(pid) + "/status", "VmRSS");
}

}  // namespace slapse::bench
