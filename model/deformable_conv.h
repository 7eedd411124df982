#pragma once
// A 3x3 deformable convolution (Dai et al. 2017, "v1": offsets, no modulation)
// built from stable LibTorch ops, since no deformable-conv kernel ships with
// Debian's LibTorch.
//
// A small conv predicts, per output pixel, a (dx, dy) offset for each of the
// 9 kernel taps. The input is bilinearly sampled at the 9 shifted positions
// (grid_sample, zeros outside the image) and the samples are combined with the
// kernel weights. The offset conv starts at zero, so a fresh layer is exactly a
// regular 3x3 conv with padding 1 and stride 1.

#include <torch/torch.h>

namespace dispmvs::model {

class DeformableConv2dImpl : public torch::nn::Module {
 public:
  static constexpr int64_t kKernel = 3;
  static constexpr int64_t kTaps = kKernel * kKernel;

  DeformableConv2dImpl(int64_t in_channels, int64_t out_channels, bool bias = true);

  // x [B, in, H, W] -> [B, out, H, W], offsets predicted from x.
  torch::Tensor forward(const torch::Tensor& x);

  // Same, with explicit offsets [B, 2*9, H, W]: channel 2k is the x (column)
  // shift and 2k+1 the y (row) shift, in pixels, of tap k (row-major over the
  // 3x3 kernel). Exposed for tests and for callers that predict offsets
  // elsewhere.
  torch::Tensor forward_with_offsets(const torch::Tensor& x, const torch::Tensor& offsets);

  torch::nn::Conv2d offset_conv() const { return offset_conv_; }
  // [out, in, 3, 3], laid out like torch::nn::Conv2d's weight.
  const torch::Tensor& weight() const { return weight_; }
  // [out], undefined when built without bias.
  const torch::Tensor& bias() const { return bias_; }

 private:
  // Throws std::invalid_argument unless x is [B, in_channels, H, W].
  void CheckInput(const torch::Tensor& x) const;

  int64_t in_channels_;
  int64_t out_channels_;
  torch::nn::Conv2d offset_conv_{nullptr};
  torch::Tensor weight_;
  torch::Tensor bias_;
};
TORCH_MODULE(DeformableConv2d);

}  // namespace dispmvs::model
