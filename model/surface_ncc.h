#pragma once
// The photometric refinement's inner step (photometric_refinement.h): the
// normalised cross-correlation of every reference window against a source
// image sampled where each reference pixel projects at its own inverse depth
// on a surface.
//
// Every hypothesis of the search and every propagated candidate is one such
// call, so it is most of the refinement's time. On CPU float tensors each
// source is one streaming pass per band of 64 rows (bands in parallel, so
// one source uses every thread): rows are projected and sampled
// (bilinearly) into a ring as the window reaches them, the window's column
// sums move down with it, and only the NCC and its flags are written,
// instead of some twenty LibTorch operations that each write a full-size
// tensor. Other devices and types run those operations (the same
// arithmetic; surface_ncc_test.cc checks the two against each other).

#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::model {

struct SurfaceCorrelation {
  torch::Tensor ncc;  // [B*N,1,H,W]
  torch::Tensor ok;   // [B*N,1,H,W] bool: the window lies inside the source and is not flat
};

// source: [B*N,1,H,W] grey source images (N sources per batch item, batch
// item-major); reference, reference_mean, reference_var: [B,1,H,W] the
// reference's grey values and their window mean and variance, shared by the
// batch item's N sources (or [B*N,1,H,W], repeated per source: the same
// result, N times the memory); a: [B*N,3,H,W] and b: [B*N,3,H,W] or [B*N,3,1,1], the epipolar
// pair of geometry.h (a reference pixel at inverse depth w projects to the
// source's homogeneous a + w b); surface: [B,1,H,W] inverse depth per
// reference pixel (<= 0: no surface). A source pixel counts (ok) where its
// match is in front of the source, at least `margin` pixels inside its
// image, and the sampled window is not flat. Throws std::invalid_argument
// on mismatched shapes.
SurfaceCorrelation CorrelateAlongSurface(const torch::Tensor& source, const torch::Tensor& reference,
                                         const torch::Tensor& reference_mean,
                                         const torch::Tensor& reference_var, const torch::Tensor& a,
                                         const torch::Tensor& b, const torch::Tensor& surface,
                                         int64_t radius, double margin);

// The same by LibTorch operations on any device (what the CPU float path
// is checked against).
SurfaceCorrelation CorrelateAlongSurfaceByOps(const torch::Tensor& source, const torch::Tensor& reference,
                                              const torch::Tensor& reference_mean,
                                              const torch::Tensor& reference_var, const torch::Tensor& a,
                                              const torch::Tensor& b, const torch::Tensor& surface,
                                              int64_t radius, double margin);

// The refinement's score of a surface: per reference pixel, the mean over
// the sources `weights` ([B,N,H,W], 0 or 1) selects of their NCC, a selected
// source whose match does not count (ok false) counting -1; -1 where no
// source is selected. [B,1,H,W]. The same as CombineSources of
// CorrelateAlongSurface, but on CPU float tensors without writing any
// per-source map: each band of rows sums its sources' NCC at once, and a
// source no pixel of the band selects is not sampled there.
torch::Tensor ScoreAlongSurface(const torch::Tensor& source, const torch::Tensor& reference,
                                const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                                const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface,
                                const torch::Tensor& weights, int64_t radius, double margin);

// The same by LibTorch operations (CorrelateAlongSurfaceByOps, then
// CombineSources), on any device.
torch::Tensor ScoreAlongSurfaceByOps(const torch::Tensor& source, const torch::Tensor& reference,
                                    const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                                    const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface,
                                    const torch::Tensor& weights, int64_t radius, double margin);

// The score above from per-source correlations ([B*N,1,H,W] each) and
// weights [B,N,H,W].
torch::Tensor CombineSources(const SurfaceCorrelation& correlation, const torch::Tensor& weights);

}  // namespace dispmvs::model
