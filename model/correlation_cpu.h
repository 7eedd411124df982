#pragma once
// The epipolar correlation lookup fused into one CPU pass, with its gradient.
//
// EpipolarCorrelation::Lookup computes, for every (pair, pixel, level,
// sample), <f_ref, bilinear(f_src_level, p)> / C. Written with ATen ops it
// runs one grid_sample per sample and level, each writing a [B,C,h,w] map
// that a multiplication and a channel sum then read again: at the fine stage
// of 640x480 with 4 sources that was about a quarter of a view's time, most
// of it moving memory. This pass reads each source pixel's C features once
// per corner from a channels-last copy of the level (C contiguous floats)
// and writes only the [B, levels*samples, h, w] dot products.
//
// Same arithmetic as the ATen path (bilinear weights of grid_sample with
// align_corners = false and zero padding, non-finite or far coordinates
// reading 0), summed in another order: equal to float rounding
// (correlation_test checks both against each other).
//
// Training: with autograd on, the lookup is an autograd node whose backward
// is a second fused pass (each sample's bilinear weights scatter grad * ref
// into the source corners and gather grad * source into the reference
// pixel). The ATen path's backward zero-filled and summed a full [B,C,H,W]
// gradient per grid_sample and kept every sampled map for it: at the
// training size (640x480, batch 2, 5 sources) the lookups' forward and
// backward took about a quarter of a step (docs/benchmarks.md). The fused
// node differentiates w.r.t. the features only, not the sample positions:
// the network detaches its matches, so training never needs that; a lookup
// that does (a test's gradient to the E-flow) stays on the ATen ops.

#include <cstdint>
#include <vector>

#include <torch/torch.h>

namespace dispmvs::model {

// Whether the fused pass takes these features: CPU float32.
bool FusedCorrelationTakes(const torch::Tensor& features);

// Whether the fused pass can serve a lookup: it takes both feature maps, and
// no gradient is wanted w.r.t. the sample positions `match` and `dir`
// (autograd off, or neither requires one).
bool CanUseFusedCorrelation(const torch::Tensor& source_features,
                            const torch::Tensor& ref_features, const torch::Tensor& match,
                            const torch::Tensor& dir);

// levels_hwc: the pyramid, level l as [B, H_l, W_l, C] contiguous float
// (e.g. permute(0,2,3,1).contiguous() of a [B,C,H_l,W_l] level).
// ref_features [B,C,h,w] float, any strides; match [B,2,h,w] the current
// match in stage pixels; dir [B,2,h,w]. Sample k of level l sits at the
// level-l pixel (match + 0.5) / 2^l - 0.5 + (k - (samples-1)/2) * dir, as in
// correlation.h. Returns [B, levels*samples, h, w] float32, channel
// l * samples + k. With autograd on and a level or ref_features requiring
// a gradient, the result is differentiable w.r.t. them (then match and dir
// must not require one). Throws std::invalid_argument on bad shapes, types
// or a gradient wanted w.r.t. match or dir.
torch::Tensor FusedCorrelationLookup(const std::vector<torch::Tensor>& levels_hwc,
                                     const torch::Tensor& ref_features,
                                     const torch::Tensor& match, const torch::Tensor& dir,
                                     int64_t samples);

}  // namespace dispmvs::model
