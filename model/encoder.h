#pragma once
// The two U-Net-shaped image encoders of DispMVS.
//
// Both take images [B,3,H,W] with values in [0,1] (H and W multiples of 16; the
// driver pads) and return a two-level feature pyramid:
//   coarse [B, C_coarse, H/16, W/16]   fine [B, C_fine, H/4, W/4].
// The encoder downsamples to 1/16 and decodes back to 1/4 with skip
// connections, so the fine features see the coarse context.
//
//  * MatchingEncoder (every view): instance norm, as in the release; outputs
//    config.match_coarse_channels / config.match_fine_channels.
//  * ContextEncoder (reference view only): outputs, raw, hidden_coarse +
//    context_input_coarse channels at 1/16 and hidden_fine + context_input_fine
//    at 1/4; the driver splits them into tanh(hidden) and relu(input). Its
//    decoder uses the deformable convolution when
//    config.deformable_context_decoder is set.

#include <torch/torch.h>

#include "model/config.h"

namespace dispmvs::model {

struct FeaturePyramid {
  torch::Tensor coarse;  // [B, C, H/16, W/16]
  torch::Tensor fine;    // [B, C', H/4, W/4]
};

// Layers shared by both encoders; see encoder.cc.
class UNetEncoderImpl;

class MatchingEncoderImpl : public torch::nn::Module {
 public:
  explicit MatchingEncoderImpl(const ModelConfig& config);
  FeaturePyramid forward(const torch::Tensor& images);

 private:
  std::shared_ptr<UNetEncoderImpl> net_;
};
TORCH_MODULE(MatchingEncoder);

class ContextEncoderImpl : public torch::nn::Module {
 public:
  explicit ContextEncoderImpl(const ModelConfig& config);
  FeaturePyramid forward(const torch::Tensor& images);

 private:
  std::shared_ptr<UNetEncoderImpl> net_;
};
TORCH_MODULE(ContextEncoder);

}  // namespace dispmvs::model
