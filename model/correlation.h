#pragma once
// Epipolar correlation of DispMVS: the 2D cost volume that the update block
// reads at every iteration (paper Eq. 12, docs/method.md section 6
// "Correlation").
//
// Built once per stage from the source-view features; then, for every
// reference pixel, Lookup() samples `samples` points per pyramid level along
// the epipolar line in the source view, centred on the current match, and
// returns their similarity with the reference feature.
//
// Conventions (all coordinates are pixel indices: pixel (row i, col j) has its
// centre at (x, y) = (j, i), as in geometry.h):
//  * Level 0 is the stage's feature map; level l is it average-pooled l times
//    by 2x2 (ceil mode, so a 1-pixel-wide map stays 1 pixel wide).
//  * The current match is c = base + dir * eflow (stage pixels). A stage point
//    x has the level-l pixel coordinate (x + 0.5) / 2^l - 0.5 (pixel centres of
//    a 2x2 pool sit in the middle of the pooled block).
//  * Sample k (k = 0 .. samples-1) sits at offset o_k = k - (samples-1)/2 along
//    `dir`, in pixels OF THAT LEVEL: level-l coordinate
//        (c + 0.5) / 2^l - 0.5 + o_k * dir,
//    i.e. o_k * 2^l stage pixels from the match. Coarser levels thus look
//    further along the line with the same number of samples (as RAFT's
//    correlation pyramid).
//  * Samples are read with bilinear interpolation; whatever part of the
//    interpolation footprint falls outside the map contributes 0.
//  * Similarity = <f_ref, f_src> / C (dot product over channels, divided by
//    the channel count).
// Output channel index = level * samples + k.

#include <cstdint>
#include <vector>

#include <torch/torch.h>

namespace dispmvs::model {

struct CorrelationSamples {
  torch::Tensor cost;    // [B, levels*samples, h, w] similarities
  torch::Tensor inside;  // [B, levels*samples, h, w] bool: sample centre inside its level's map
};

// Which implementation a correlation runs. kAuto: the fused CPU passes of
// correlation_cpu.h wherever they apply (CPU float32 features and no
// gradient wanted w.r.t. the match: inference, and training, whose matches
// are detached), ATen ops elsewhere (a GPU, float64, a gradient to the
// E-flow). kAtenOps: always the ATen ops, the reference that tests and
// benchmarks compare the fused passes with.
enum class CorrelationImpl { kAuto, kAtenOps };

class EpipolarCorrelation {
 public:
  // source_features [B, C, H, W]; levels >= 1, samples >= 1.
  // Throws std::invalid_argument on a bad shape or count.
  EpipolarCorrelation(const torch::Tensor& source_features, int64_t levels, int64_t samples,
                      CorrelationImpl impl = CorrelationImpl::kAuto);

  // ref_features [B, C, h, w]; base_xy, dir [B, 2, h, w] (stage pixels; dir a
  // unit vector or 0); eflow [B, 1, h, w]. The reference grid (h, w) need not
  // equal the source map's size. Differentiable w.r.t. features and eflow.
  CorrelationSamples Lookup(const torch::Tensor& ref_features, const torch::Tensor& base_xy,
                            const torch::Tensor& dir, const torch::Tensor& eflow) const;

  int64_t levels() const { return static_cast<int64_t>(pyramid_.size()); }
  int64_t samples() const { return samples_; }
  int64_t channels() const { return levels() * samples_; }
  // Level l of the pooled source pyramid, [B, C, H_l, W_l].
  const torch::Tensor& level(int64_t l) const { return pyramid_.at(static_cast<size_t>(l)); }

 private:
  std::vector<torch::Tensor> pyramid_;
  // The levels as [B,H_l,W_l,C] (autograd tracks the copy), made only for
  // CPU float features under kAuto, where Lookup runs the fused pass of
  // correlation_cpu.h; empty otherwise.
  std::vector<torch::Tensor> levels_hwc_;
  int64_t samples_;
};

}  // namespace dispmvs::model
