#pragma once
// A portable seeded random source for the generator. std::mt19937_64 is specified bit for bit
// by the standard, but the std:: distributions are not, so uniform and normal variates are
// computed here: same seed -> same dataset on every platform and compiler.

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace th::synth {

class Rng {
 public:
  explicit Rng(uint64_t seed) : engine_(seed) {}

  // An independent stream for (seed, a, b): people, motion, cameras and noise draw from their
  // own streams so that changing one option (e.g. the frame count) leaves the others alone.
  static Rng stream(uint64_t seed, uint64_t a, uint64_t b = 0) {
    return Rng(mix(mix(mix(seed) ^ (a * 0x9E3779B97F4A7C15ull)) ^ (b + 0x632BE59BD9B4E019ull)));
  }

  uint64_t bits() { return engine_(); }
  // Uniform in [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Standard normal by Box-Muller (one value per call, two uniforms consumed).
  double normal() {
    const double u1 = 1.0 - uniform();  // (0, 1]
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }
  double normal(double mean, double std) { return mean + std * normal(); }
  // Uniform integer in [0, n) without modulo bias.
  uint64_t below(uint64_t n) {
    const uint64_t limit = ~0ull - (~0ull % n);
    uint64_t x;
    do x = engine_();
    while (x >= limit);
    return x % n;
  }
  bool chance(double p) { return uniform() < p; }
  template <class T>
  const T& pick(const std::vector<T>& items) {
    return items[below(items.size())];
  }

 private:
  // splitmix64 finaliser.
  static uint64_t mix(uint64_t z) {
    z += 0x9E3779B97F4A7C15ull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  std::mt19937_64 engine_;
};

}  // namespace th::synth
