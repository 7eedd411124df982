#include "model/deformable_conv.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace dispmvs::model {
namespace F = torch::nn::functional;

DeformableConv2dImpl::DeformableConv2dImpl(int64_t in_channels, int64_t out_channels, bool bias)
    : in_channels_(in_channels), out_channels_(out_channels) {
  if (in_channels < 1 || out_channels < 1) {
    throw std::invalid_argument("DeformableConv2d: channel counts must be >= 1, got " +
                                std::to_string(in_channels) + " -> " +
                                std::to_string(out_channels));
  }
  offset_conv_ = register_module(
      "offset_conv",
      torch::nn::Conv2d(torch::nn::Conv2dOptions(in_channels, 2 * kTaps, kKernel).padding(1)));
  // Zero offsets: a fresh layer behaves exactly like a regular conv, and
  // training bends the sampling grid only where that helps.
  {
    torch::NoGradGuard no_grad;
    offset_conv_->weight.zero_();
    offset_conv_->bias.zero_();
  }
  // Same initialisation as torch::nn::Conv2d (kaiming_uniform with a = sqrt(5)
  // reduces to U(-1/sqrt(fan_in), 1/sqrt(fan_in)) for weight and bias).
  const double bound = 1.0 / std::sqrt(static_cast<double>(in_channels * kTaps));
  weight_ = register_parameter(
      "weight",
      torch::empty({out_channels, in_channels, kKernel, kKernel}).uniform_(-bound, bound));
  if (bias) {
    bias_ = register_parameter("bias", torch::empty({out_channels}).uniform_(-bound, bound));
  }
}

void DeformableConv2dImpl::CheckInput(const torch::Tensor& x) const {
  if (x.dim() != 4 || x.size(1) != in_channels_) {
    throw std::invalid_argument("DeformableConv2d: expected input [B," +
                                std::to_string(in_channels_) + ",H,W], got " + c10::str(x.sizes()));
  }
}

torch::Tensor DeformableConv2dImpl::forward(const torch::Tensor& x) {
  CheckInput(x);
  return forward_with_offsets(x, offset_conv_->forward(x));
}

torch::Tensor DeformableConv2dImpl::forward_with_offsets(const torch::Tensor& x,
                                                         const torch::Tensor& offsets) {
  CheckInput(x);
  const int64_t batch = x.size(0), height = x.size(2), width = x.size(3);
  if (offsets.dim() != 4 || offsets.size(0) != batch || offsets.size(1) != 2 * kTaps ||
      offsets.size(2) != height || offsets.size(3) != width) {
    throw std::invalid_argument("DeformableConv2d: expected offsets [" + std::to_string(batch) +
                                ",18," + std::to_string(height) + "," + std::to_string(width) +
                                "], got " + c10::str(offsets.sizes()));
  }
  const torch::Tensor shifts = offsets.to(x.dtype());
  const auto options = x.options();
  const torch::Tensor cols = torch::arange(width, options).view({1, 1, width});
  const torch::Tensor rows = torch::arange(height, options).view({1, height, 1});
  const torch::Tensor weight = weight_.to(x.dtype());

  // One tap at a time: each tap is a bilinear resampling of x followed by a
  // 1x1 conv with that tap's weights. Summing the 9 partial results needs one
  // input-sized buffer at a time instead of a 9x larger im2col matrix, which
  // matters at 1/4 resolution of a large image.
  torch::Tensor out;
  for (int64_t ky = 0; ky < kKernel; ++ky) {
    for (int64_t kx = 0; kx < kKernel; ++kx) {
      const int64_t tap = ky * kKernel + kx;
      // Sampling position in pixel-index coordinates (column, row).
      const torch::Tensor px = cols + static_cast<double>(kx - 1) + shifts.select(1, 2 * tap);
      const torch::Tensor py = rows + static_cast<double>(ky - 1) + shifts.select(1, 2 * tap + 1);
      // To grid_sample's [-1, 1] coordinates. align_corners=false, where pixel
      // p maps to (2p + 1) / size - 1, is exact for every size; with
      // align_corners=true a size-1 axis would send every position (even
      // out-of-image ones) to pixel 0 instead of the zero padding.
      const torch::Tensor grid = torch::stack({(2 * px + 1) / static_cast<double>(width) - 1,
                                               (2 * py + 1) / static_cast<double>(height) - 1},
                                              /*dim=*/-1);
      const torch::Tensor sampled = F::grid_sample(x, grid,
                                                   F::GridSampleFuncOptions()
                                                       .mode(torch::kBilinear)
                                                       .padding_mode(torch::kZeros)
                                                       .align_corners(false));
      const torch::Tensor tap_weight =
          weight.select(3, kx).select(2, ky).view({out_channels_, in_channels_, 1, 1});
      const torch::Tensor partial = F::conv2d(sampled, tap_weight);
      out = out.defined() ? out + partial : partial;
    }
  }
  if (bias_.defined()) out = out + bias_.to(x.dtype()).view({1, out_channels_, 1, 1});
  return out;
}

}  // namespace dispmvs::model
