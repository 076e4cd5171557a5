// This process's resident set size, for the benches (timing and memory live
// in bench/, never in tests).
#pragma once

#include <cstdlib>
#include <fstream>
#include <string>

namespace slapse::bench {

// A "<key>: <n> kB" field of /proc/self/status, KiB; -1 if it cannot be read.
inline long StatusKb(const std::string& key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key + ":", 0) == 0) return std::atol(line.c_str() + key.size() + 1);
  }
  return -1;
}

// VmRSS: all resident pages, shared libraries' included.
inline long RssKb() { return StatusKb("VmRSS"); }
// RssAnon: the resident pages no file backs (heap, arenas, stacks).
inline long RssAnonKb() { return StatusKb("RssAnon"); }

}  // namespace slapse::bench
