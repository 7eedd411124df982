#pragma once
// Deterministic scalar random numbers for scene layout.
//
// Why not <random> distributions: std::uniform_real_distribution and friends
// are implementation-defined, so the same seed could give different scenes
// with another standard library. This generator (SplitMix64) and the
// transforms below are fully specified here, so a seed names one scene.

#include <cmath>
#include <cstdint>

namespace dispmvs::synth {

// One SplitMix64 step as a hash: x plus the golden-ratio increment, then the
// finaliser. Well mixed and identical on every platform (unlike std::hash),
// so seeds derived with it (scenes, training samples, textures) name the
// same thing everywhere.
constexpr uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

class Rng {
 public:
  explicit Rng(uint64_t seed) : state_(seed) {}

  // The stream is SplitMix64 of seed, seed + increment, seed + 2 increments...
  uint64_t NextU64() {
    const uint64_t z = SplitMix64(state_);
    state_ += 0x9E3779B97F4A7C15ull;
    return z;
  }
  // Uniform in [0, 1) with 53 random bits.
  double Uniform() { return static_cast<double>(NextU64() >> 11) * 0x1.0p-53; }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  // Log-uniform in [lo, hi], lo > 0: every order of magnitude equally likely.
  double LogUniform(double lo, double hi) {
    return std::exp(Uniform(std::log(lo), std::log(hi)));
  }
  // Integer uniform in [lo, hi] (inclusive).
  int64_t Int(int64_t lo, int64_t hi) {
    return lo + static_cast<int64_t>(Uniform() * static_cast<double>(hi - lo + 1));
  }
  bool Bernoulli(double p) { return Uniform() < p; }
  // Standard normal (Box-Muller; one draw per call keeps the stream simple).
  double Normal() {
    const double u1 = 1.0 - Uniform();  // (0, 1]
    const double u2 = Uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }
  // An independent generator for a named sub-task, so that changing how many
  // numbers one part of the generator draws does not reshuffle the others.
  Rng Fork(uint64_t tag) {
    Rng mixer(state_ ^ (tag * 0xD1B54A32D192ED03ull));
    return Rng(mixer.NextU64());
  }

 private:
  uint64_t state_;
};

}  // namespace dispmvs::synth
