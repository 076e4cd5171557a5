// Deterministic randomness for the simulator.
//
// Everything the simulator makes is a pure function of the seed. Draws go
// through SimRandom (std::mt19937_64, explicitly seeded, with our own uniform
// and normal transforms, so results do not depend on how a standard library
// implements its distributions). Textures use stateless hashes of integer
// coordinates instead, so any tile can be regenerated alone, in any order.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>

namespace slapse {

// SplitMix64 finaliser: a bijective 64-bit mix with good avalanche.
inline uint64_t Mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}
inline uint64_t HashCombine(uint64_t seed, uint64_t v) { return Mix64(seed ^ Mix64(v)); }
inline uint64_t Hash2(uint64_t seed, int64_t a, int64_t b) {
  return HashCombine(HashCombine(seed, static_cast<uint64_t>(a)), static_cast<uint64_t>(b));
}
inline uint64_t Hash3(uint64_t seed, int64_t a, int64_t b, int64_t c) {
  return HashCombine(Hash2(seed, a, b), static_cast<uint64_t>(c));
}
// Uniform in [0, 1) from the top 24 bits of a hash.
inline float HashUnit(uint64_t h) { return static_cast<float>(h >> 40) * (1.0f / 16777216.0f); }
// Uniform in [-1, 1).
inline float HashSigned(uint64_t h) { return 2.0f * HashUnit(h) - 1.0f; }

class SimRandom {
 public:
  explicit SimRandom(uint64_t seed) : engine_(seed) {}

  uint64_t NextU64() { return engine_(); }
  // Uniform in [0, 1) with 53 random bits.
  double Uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  // Uniform integer in [lo, hi].
  int UniformInt(int lo, int hi) {
    const int v = lo + static_cast<int>(Uniform() * (hi - lo + 1));
    return v > hi ? hi : v;
  }
  bool Bernoulli(double p) { return Uniform() < p; }
  // +1 or -1 with equal probability.
  double Sign() { return Bernoulli(0.5) ? 1.0 : -1.0; }
  // Standard normal by Box-Muller (one draw per call, no caching).
  double Normal() {
    const double u1 = 1.0 - Uniform();  // (0, 1]
    const double u2 = Uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }
  double Normal(double mean, double sigma) { return mean + sigma * Normal(); }

 private:
  std::mt19937_64 engine_;
};

}  // namespace slapse
