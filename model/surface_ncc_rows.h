#pragma once
// The inner loop of surface_ncc.h on the CPU: one band of rows of one source
// plane in one streaming pass (sample the source where each reference pixel
// projects at its inverse depth, move the window sums down, write the NCC).
// Standard library only. Two builds of the same arithmetic:
//  * CorrelateRowsPortable: scalar, for any x86-64 (Debian's baseline) or
//    other architecture;
//  * CorrelateRowsAvx2: the projection and bilinear weights of eight pixels
//    at a time (sampling was about half of the scalar pass's time), and the
//    window sums and NCC of eight pixels at a time, on processors with AVX2
//    and FMA: 2.35x faster on a 640x480 plane
//    (bench/surface_ncc_microbench.cc, docs/benchmarks.md).
// CorrelateRows picks the AVX2 build where the processor has it. The two
// agree to float rounding (FMA contracts some products); surface_ncc_test.cc
// checks them against each other and against LibTorch's operations.

#include <cstdint>

namespace dispmvs::model {

// One source plane's sampling: where reference pixel p, at inverse depth
// surface[p], falls in the source (bilinear, zero outside the image, as
// grid_sample with align_corners), and whether the match counts.
struct PlaneSampler {
  const float* source;
  const float* a;  // [3,H,W]
  const float* b;  // [3,H,W] or [3]
  const float* surface;
  int64_t h, w;
  bool b_per_pixel;
  float half_w, half_h, limit_x, limit_y;

  // The sample of reference pixel p (row-major index), and in *inside
  // whether it counts: in front of the source, within limit_x, limit_y of
  // the image's centre.
  float Sample(int64_t p, bool* inside) const;
};

// Rows [row_begin, row_end) of one source plane: ncc and ok point at
// row_begin's first pixel; reference, reference_mean, reference_var at the
// plane's first pixel. `needed` (null: every pixel), like ncc from
// row_begin: the pixels whose NCC is wanted; the others get ncc 0, ok false.
void CorrelateRowsPortable(const PlaneSampler& sampler, const float* reference, const float* reference_mean,
                           const float* reference_var, int64_t r, int64_t row_begin, int64_t row_end, float* ncc,
                           bool* ok, const float* needed);

// The same with AVX2 and FMA; call only where CpuHasAvx2Fma() and
// Avx2RowsFit(sampler.h, sampler.w).
void CorrelateRowsAvx2(const PlaneSampler& sampler, const float* reference, const float* reference_mean,
                       const float* reference_var, int64_t r, int64_t row_begin, int64_t row_end, float* ncc,
                       bool* ok, const float* needed);

// Whether this build and processor run CorrelateRowsAvx2 (x86-64 with GCC
// or Clang, and a processor with AVX2 and FMA); whether a plane suits it
// (at least two rows, small enough for its 32-bit pixel offsets).
bool CpuHasAvx2Fma();
bool Avx2RowsFit(int64_t h, int64_t w);

// CorrelateRowsAvx2 where CpuHasAvx2Fma() and Avx2RowsFit(), else the
// portable build.
void CorrelateRows(const PlaneSampler& sampler, const float* reference, const float* reference_mean,
                   const float* reference_var, int64_t r, int64_t row_begin, int64_t row_end, float* ncc, bool* ok,
                   const float* needed);

}  // namespace dispmvs::model
