#include "synth/hash_noise.h"

#include <stdexcept>

namespace dispmvs::synth {
namespace {

constexpr int64_t kLow32 = 0xFFFFFFFFll;

// One avalanche round on values in [0, 2^32): multiplier < 2^31, so the
// product stays below 2^63.
torch::Tensor Mix(const torch::Tensor& h, int64_t multiplier, int shift) {
  torch::Tensor x = torch::bitwise_xor(h, torch::div(h, int64_t{1} << shift, "floor"));
  return torch::bitwise_and(x * multiplier, kLow32);
}

}  // namespace

torch::Tensor HashBits(const torch::Tensor& key) {
  // Two multiply / xor-shift rounds: enough mixing that textures and sensor
  // noise show no lattice structure (see the uniformity and correlation tests).
  torch::Tensor h = torch::bitwise_and(key, kLow32);
  h = Mix(h, 1274126177, 13);
  return Mix(h, 1013904223, 16);
}

namespace {

// Lattice key of (ix, iy, seed) before mixing. Coordinates are clamped to
// +-2^30, so |key| < 2^62 (no overflow) and key(ix + 1, iy) = key + kStepX,
// key(ix, iy + 1) = key + kStepY exactly; the hash only reads the key's low
// 32 bits, which are well defined for negative keys too.
constexpr int64_t kStepX = 374761393, kStepY = 668265263, kStepSeed = 2654435;
constexpr int64_t kMaxCoordinate = int64_t{1} << 30;
torch::Tensor LatticeKey(const torch::Tensor& ix, const torch::Tensor& iy, const torch::Tensor& seed) {
  return torch::clamp(ix, -kMaxCoordinate, kMaxCoordinate) * kStepX +
         torch::clamp(iy, -kMaxCoordinate, kMaxCoordinate) * kStepY + torch::bitwise_and(seed, kLow32) * kStepSeed;
}

torch::Tensor KeyToUnit(const torch::Tensor& key, torch::ScalarType dtype) {
  return HashBits(key).to(dtype) * (1.0 / 4294967296.0);
}

}  // namespace

torch::Tensor HashCellBits(const torch::Tensor& ix, const torch::Tensor& iy, uint32_t seed) {
  return HashBits(LatticeKey(ix, iy, torch::full({}, static_cast<int64_t>(seed), ix.options().dtype(torch::kLong))));
}

torch::Tensor HashUnit(const torch::Tensor& ix, const torch::Tensor& iy, const torch::Tensor& seed,
                       torch::ScalarType dtype) {
  return KeyToUnit(LatticeKey(ix, iy, seed), dtype);
}

torch::Tensor HashUnit(const torch::Tensor& ix, const torch::Tensor& iy, uint32_t seed,
                       torch::ScalarType dtype) {
  return HashUnit(ix, iy, torch::full({}, static_cast<int64_t>(seed), ix.options().dtype(torch::kLong)), dtype);
}

torch::Tensor ValueNoise(const torch::Tensor& u, const torch::Tensor& v, const torch::Tensor& seed) {
  const torch::Tensor fu = torch::floor(u), fv = torch::floor(v);
  const torch::Tensor iu = fu.to(torch::kLong), iv = fv.to(torch::kLong);
  torch::Tensor su = u - fu, sv = v - fv;
  su = su * su * (3 - 2 * su);
  sv = sv * sv * (3 - 2 * sv);
  const auto dtype = u.scalar_type();
  // Corner keys by offsetting one key (exact, see LatticeKey).
  const torch::Tensor key = LatticeKey(iu, iv, seed);
  const torch::Tensor v00 = KeyToUnit(key, dtype);
  const torch::Tensor v10 = KeyToUnit(key + kStepX, dtype);
  const torch::Tensor v01 = KeyToUnit(key + kStepY, dtype);
  const torch::Tensor v11 = KeyToUnit(key + (kStepX + kStepY), dtype);
  const torch::Tensor bottom = v00 + (v10 - v00) * su;
  const torch::Tensor top = v01 + (v11 - v01) * su;
  return bottom + (top - bottom) * sv;
}

torch::Tensor ValueNoise(const torch::Tensor& u, const torch::Tensor& v, uint32_t seed) {
  return ValueNoise(u, v, torch::full({}, static_cast<int64_t>(seed), u.options().dtype(torch::kLong)));
}

torch::Tensor FractalNoise(const torch::Tensor& u, const torch::Tensor& v, const torch::Tensor& seed,
                           int octaves, double gain) {
  if (octaves < 1 || octaves > 16) throw std::invalid_argument("FractalNoise: octaves must be in [1, 16]");
  torch::Tensor sum = torch::zeros_like(u);
  double amplitude = 1.0, total = 0.0, frequency = 1.0;
  for (int k = 0; k < octaves; ++k) {
    // A per-octave offset avoids all octaves sharing the lattice origin.
    const double offset = 17.31 * k;
    sum = sum + amplitude * ValueNoise(u * frequency + offset, v * frequency - offset, seed + 7919 * k);
    total += amplitude;
    amplitude *= gain;
    frequency *= 2.0;
  }
  return sum / total;
}

torch::Tensor FractalNoise(const torch::Tensor& u, const torch::Tensor& v, uint32_t seed,
                           int octaves, double gain) {
  return FractalNoise(u, v, torch::full({}, static_cast<int64_t>(seed), u.options().dtype(torch::kLong)),
                      octaves, gain);
}

torch::Tensor HashNormal(const torch::Tensor& ix, const torch::Tensor& iy, uint32_t seed,
                         torch::ScalarType dtype) {
  // Box-Muller in double for the log, then cast: 1 - u1 is in (0, 1].
  const torch::Tensor u1 = 1.0 - HashUnit(ix, iy, seed, torch::kDouble);
  const torch::Tensor u2 = HashUnit(ix, iy, seed ^ 0x9E3779B9u, torch::kDouble);
  return (torch::sqrt(-2.0 * torch::log(u1)) * torch::cos(6.283185307179586 * u2)).to(dtype);
}

}  // namespace dispmvs::synth
