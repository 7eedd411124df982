#pragma once
// Stateless, device-generic pseudo-random fields evaluated with integer
// tensor ops: the value at a lattice point depends only on its integer
// coordinates and a seed. This is what lets a surface point have the same
// texture in every view (the texture is a function of (texture, UV), not of
// the order pixels are visited), and lets per-pixel sensor noise be
// reproducible on CPU and CUDA without a device random generator.
//
// All integer arithmetic stays below 2^63 (no signed overflow): coordinates
// are clamped to +-2^30 and intermediate hashes reduced to 32 bits.

#include <torch/torch.h>

#include <cstdint>

namespace dispmvs::synth {

// 32 well-mixed bits (int64 values in [0, 2^32)) of a non-negative int64
// key below 2^62.
torch::Tensor HashBits(const torch::Tensor& key);

// HashBits of the lattice point (ix, iy) (int64 tensors) and a seed.
torch::Tensor HashCellBits(const torch::Tensor& ix, const torch::Tensor& iy, uint32_t seed);

// Uniform values in [0, 1) of floating type `dtype` for
// integer lattice coordinates ix, iy (int64 tensors of equal shape).
torch::Tensor HashUnit(const torch::Tensor& ix, const torch::Tensor& iy, uint32_t seed,
                       torch::ScalarType dtype);
// The same with one seed per point: `seed` is an int64 tensor of values in
// [0, 2^32) broadcastable to ix (equal to the scalar version where equal).
torch::Tensor HashUnit(const torch::Tensor& ix, const torch::Tensor& iy, const torch::Tensor& seed,
                       torch::ScalarType dtype);

// Value noise in [0, 1): lattice values from HashUnit, blended with a C1
// smoothstep. u, v: floating tensors of equal shape.
torch::Tensor ValueNoise(const torch::Tensor& u, const torch::Tensor& v, uint32_t seed);
torch::Tensor ValueNoise(const torch::Tensor& u, const torch::Tensor& v, const torch::Tensor& seed);

// Fractal (multi-octave) value noise in [0, 1): octave k has frequency 2^k
// and amplitude `gain`^k; normalised by the sum of amplitudes.
torch::Tensor FractalNoise(const torch::Tensor& u, const torch::Tensor& v, uint32_t seed,
                           int octaves, double gain = 0.5);
// Per-point seeds (int64 tensor broadcastable to u, values in [0, 2^32)):
// many textures' noise in one batched evaluation.
torch::Tensor FractalNoise(const torch::Tensor& u, const torch::Tensor& v, const torch::Tensor& seed,
                           int octaves, double gain = 0.5);

// Standard normal values from two hashed uniforms (Box-Muller).
torch::Tensor HashNormal(const torch::Tensor& ix, const torch::Tensor& iy, uint32_t seed,
                         torch::ScalarType dtype);

}  // namespace dispmvs::synth
