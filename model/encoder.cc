#include "model/encoder.h"

#include <stdexcept>
#include <string>

#include "model/deformable_conv.h"

namespace dispmvs::model {
namespace F = torch::nn::functional;
namespace {

enum class Norm {
  // Per image and channel, no learned affine (RAFT's feature encoder, the
  // release's matching encoder): matching features of different views then
  // share one scale regardless of exposure.
  kInstance,
  // Group norm, used by the context encoder. RAFT's context net uses batch
  // norm, but with batch size 1 at inference and 1-4 in training its batch
  // statistics are noisy and differ between train and eval. Group norm is
  // batch-independent like instance norm, yet normalises over groups of
  // channels, so the relative strength of channels within a group (contrast,
  // texture energy: useful context for the GRU) survives.
  kGroup,
};

// Largest divisor of `channels` that is at most 8.
int64_t GroupCount(int64_t channels) {
  for (int64_t groups = 8; groups > 1; --groups) {
    if (channels % groups == 0) return groups;
  }
  return 1;
}

torch::nn::AnyModule MakeNorm(Norm norm, int64_t channels) {
  if (norm == Norm::kInstance) {
    return torch::nn::AnyModule(
        torch::nn::InstanceNorm2d(torch::nn::InstanceNorm2dOptions(channels)));
  }
  return torch::nn::AnyModule(
      torch::nn::GroupNorm(torch::nn::GroupNormOptions(GroupCount(channels), channels)));
}

// Convs followed by a norm have no bias: the norm's mean subtraction would
// cancel it (its gradient would be exactly zero under instance norm).
torch::nn::Conv2d Conv(int64_t in, int64_t out, int64_t kernel, int64_t stride) {
  return torch::nn::Conv2d(
      torch::nn::Conv2dOptions(in, out, kernel).stride(stride).padding(kernel / 2).bias(false));
}

// conv -> norm -> relu.
torch::nn::Sequential ConvNormRelu(int64_t in, int64_t out, int64_t kernel, int64_t stride,
                                   Norm norm) {
  torch::nn::Sequential seq;
  seq->push_back("conv", Conv(in, out, kernel, stride));
  seq->push_back("norm", MakeNorm(norm, out));
  seq->push_back("relu", torch::nn::ReLU());
  return seq;
}

// RAFT's residual block: two 3x3 conv-norm-relu, with a strided 1x1
// projection on the shortcut when the shape changes.
class ResidualBlockImpl : public torch::nn::Module {
 public:
  ResidualBlockImpl(int64_t in, int64_t out, int64_t stride, Norm norm) {
    first_ = register_module("first", ConvNormRelu(in, out, 3, stride, norm));
    second_ = register_module("second", ConvNormRelu(out, out, 3, 1, norm));
    if (stride != 1 || in != out) {
      torch::nn::Sequential shortcut;
      shortcut->push_back("conv", Conv(in, out, 1, stride));
      shortcut->push_back("norm", MakeNorm(norm, out));
      shortcut_ = register_module("shortcut", shortcut);
    }
  }

  torch::Tensor forward(const torch::Tensor& x) {
    const torch::Tensor y = second_->forward(first_->forward(x));
    return torch::relu((shortcut_ ? shortcut_->forward(x) : x) + y);
  }

 private:
  torch::nn::Sequential first_{nullptr};
  torch::nn::Sequential second_{nullptr};
  torch::nn::Sequential shortcut_{nullptr};
};
TORCH_MODULE(ResidualBlock);

// One decoder step: upsample the deeper features to the skip's size, fuse
// both with a 1x1 conv, then refine with a 3x3 (optionally deformable) conv.
class DecoderStepImpl : public torch::nn::Module {
 public:
  DecoderStepImpl(int64_t deep, int64_t skip, int64_t out, Norm norm, bool deformable)
      : deformable_(deformable) {
    fuse_ = register_module("fuse", ConvNormRelu(deep + skip, out, 1, 1, norm));
    if (deformable) {
      // The deformable conv lets the context features gather from outside a
      // fixed 3x3 window (e.g. along an object boundary), as in the release.
      deformable_conv_ =
          register_module("deformable_conv", DeformableConv2d(out, out, /*bias=*/false));
    } else {
      conv_ = register_module("conv", Conv(out, out, 3, 1));
    }
    norm_ = MakeNorm(norm, out);
    register_module("norm", norm_.ptr());
  }

  torch::Tensor forward(const torch::Tensor& deep, const torch::Tensor& skip) {
    const torch::Tensor up =
        F::interpolate(deep, F::InterpolateFuncOptions()
                                 .size(std::vector<int64_t>{skip.size(2), skip.size(3)})
                                 .mode(torch::kBilinear)
                                 .align_corners(false));
    const torch::Tensor fused = fuse_->forward(torch::cat({up, skip}, /*dim=*/1));
    const torch::Tensor refined =
        deformable_ ? deformable_conv_->forward(fused) : conv_->forward(fused);
    return torch::relu(norm_.forward(refined));
  }

 private:
  bool deformable_;
  torch::nn::Sequential fuse_{nullptr};
  torch::nn::Conv2d conv_{nullptr};
  DeformableConv2d deformable_conv_{nullptr};
  torch::nn::AnyModule norm_;
};
TORCH_MODULE(DecoderStep);

void CheckImages(const char* who, const torch::Tensor& images) {
  if (images.dim() != 4 || images.size(1) != 3 || images.size(2) < 1 || images.size(3) < 1) {
    throw std::invalid_argument(std::string(who) + ": expected images [B,3,H,W], got " +
                                c10::str(images.sizes()));
  }
}

}  // namespace

// The U-Net shared by both encoders. With b = base width:
//   stem 7x7/2 (b) -> 1/2, residual b -> 1/2, 2b -> 1/4, 3b -> 1/8, 4b -> 1/16,
//   one more residual block at 1/16 -> coarse head (1x1 conv);
//   decode 1/16 -> 1/8 (+ skip 3b) -> 1/4 (+ skip 2b) -> fine head (1x1 conv).
// Every stride-2 layer rounds up, so any input size works: coarse is
// ceil(H/16) x ceil(W/16) and fine ceil(H/4) x ceil(W/4).
class UNetEncoderImpl : public torch::nn::Module {
 public:
  UNetEncoderImpl(int64_t base, int64_t coarse_channels, int64_t fine_channels, Norm norm,
                  bool deformable_decoder) {
    const int64_t b = base;
    stem_ = register_module("stem", ConvNormRelu(3, b, 7, 2, norm));
    down2_ = register_module("down2", ResidualBlock(b, b, 1, norm));
    down4_ = register_module("down4", ResidualBlock(b, 2 * b, 2, norm));
    down8_ = register_module("down8", ResidualBlock(2 * b, 3 * b, 2, norm));
    down16_ = register_module("down16", ResidualBlock(3 * b, 4 * b, 2, norm));
    bottleneck_ = register_module("bottleneck", ResidualBlock(4 * b, 4 * b, 1, norm));
    coarse_head_ = register_module(
        "coarse_head", torch::nn::Conv2d(torch::nn::Conv2dOptions(4 * b, coarse_channels, 1)));
    up8_ = register_module("up8", DecoderStep(4 * b, 3 * b, 3 * b, norm, deformable_decoder));
    up4_ = register_module("up4", DecoderStep(3 * b, 2 * b, 2 * b, norm, deformable_decoder));
    fine_head_ = register_module(
        "fine_head", torch::nn::Conv2d(torch::nn::Conv2dOptions(2 * b, fine_channels, 1)));
  }

  FeaturePyramid forward(const torch::Tensor& images) {
    // [0,1] -> [-1,1], centred like the release's normalisation.
    const torch::Tensor x = 2 * images - 1;
    const torch::Tensor s2 = down2_->forward(stem_->forward(x));
    const torch::Tensor s4 = down4_->forward(s2);
    const torch::Tensor s8 = down8_->forward(s4);
    const torch::Tensor s16 = bottleneck_->forward(down16_->forward(s8));
    FeaturePyramid out;
    out.coarse = coarse_head_->forward(s16);
    out.fine = fine_head_->forward(up4_->forward(up8_->forward(s16, s8), s4));
    return out;
  }

 private:
  torch::nn::Sequential stem_{nullptr};
  ResidualBlock down2_{nullptr}, down4_{nullptr}, down8_{nullptr}, down16_{nullptr};
  ResidualBlock bottleneck_{nullptr};
  torch::nn::Conv2d coarse_head_{nullptr};
  DecoderStep up8_{nullptr}, up4_{nullptr};
  torch::nn::Conv2d fine_head_{nullptr};
};

MatchingEncoderImpl::MatchingEncoderImpl(const ModelConfig& config) {
  config.Check();
  net_ = register_module("net", std::make_shared<UNetEncoderImpl>(
                                    config.encoder_base_channels, config.match_coarse_channels,
                                    config.match_fine_channels, Norm::kInstance,
                                    /*deformable_decoder=*/false));
}

FeaturePyramid MatchingEncoderImpl::forward(const torch::Tensor& images) {
  CheckImages("MatchingEncoder", images);
  return net_->forward(images);
}

ContextEncoderImpl::ContextEncoderImpl(const ModelConfig& config) {
  config.Check();
  net_ = register_module(
      "net", std::make_shared<UNetEncoderImpl>(config.encoder_base_channels,
                                               config.hidden_coarse + config.context_input_coarse,
                                               config.hidden_fine + config.context_input_fine,
                                               Norm::kGroup, config.deformable_context_decoder));
}

FeaturePyramid ContextEncoderImpl::forward(const torch::Tensor& images) {
  CheckImages("ContextEncoder", images);
  return net_->forward(images);
}

}  // namespace dispmvs::model
