#pragma once
// The epipolar correlation lookup fused into one CPU pass, for inference.
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
// (correlation_test checks both against each other). No autograd: the
// training path keeps the ATen ops.

#include <cstdint>
#include <vector>

#include <torch/torch.h>

namespace dispmvs::model {

// Whether the fused pass can serve a lookup on these tensors: CPU, float32,
// and no gradient wanted (autograd disabled).
bool CanUseFusedCorrelation(const torch::Tensor& source_features,
                            const torch::Tensor& ref_features);

// levels_hwc: the pyramid, level l as [B, H_l, W_l, C] contiguous float
// (e.g. permute(0,2,3,1).contiguous() of a [B,C,H_l,W_l] level).
// ref_features [B,C,h,w] float, any strides; match [B,2,h,w] the current
// match in stage pixels; dir [B,2,h,w]. Sample k of level l sits at the
// level-l pixel (match + 0.5) / 2^l - 0.5 + (k - (samples-1)/2) * dir, as in
// correlation.h. Returns [B, levels*samples, h, w] float32, channel
// l * samples + k. Throws std::invalid_argument on bad shapes or types.
torch::Tensor FusedCorrelationLookup(const std::vector<torch::Tensor>& levels_hwc,
                                     const torch::Tensor& ref_features,
                                     const torch::Tensor& match, const torch::Tensor& dir,
                                     int64_t samples);

}  // namespace dispmvs::model
