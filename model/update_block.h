#pragma once
// The recurrent update block of one DispMVS stage (paper supplement "GRU
// Update"; RAFT's BasicUpdateBlock adapted to a scalar E-flow).
//
// One block per stage, shared by all source views: the driver folds the
// source views into the batch dimension, so "batch" below is B*N, and every
// (reference, source) pair carries its own hidden state.
//
//   motion   = MotionEncoder(correlation, eflow)         [hidden channels]
//   hidden'  = SepConvGRU(hidden, [motion, context])     1x5 pass then 5x1 pass
//   heads    : delta E-flow (1 ch) and fusion-weight logit (1 ch) per pair,
//              convex-upsampling mask logits (9*f*f ch), see MaskLogits().
//
// Widths scale with the hidden size; at hidden = 128 they are RAFT's
// (256/192 for the correlation branch, 128/64 for the flow branch).

#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::model {

// GRU whose gates are two separable convolutions: first 1x5 (horizontal
// context), then 5x1 (vertical), each a full GRU step (paper Eq. 17, in the
// supplement; docs/method.md section 7).
class SepConvGruImpl : public torch::nn::Module {
 public:
  SepConvGruImpl(int64_t hidden_channels, int64_t input_channels);
  torch::Tensor forward(torch::Tensor hidden, const torch::Tensor& input);

 private:
  torch::Tensor Step(const torch::Tensor& hidden, const torch::Tensor& input,
                     torch::nn::Conv2d& convz, torch::nn::Conv2d& convr,
                     torch::nn::Conv2d& convq);

  torch::nn::Conv2d convz1_{nullptr}, convr1_{nullptr}, convq1_{nullptr};
  torch::nn::Conv2d convz2_{nullptr}, convr2_{nullptr}, convq2_{nullptr};
};
TORCH_MODULE(SepConvGru);

struct UpdateBlockOutput {
  torch::Tensor hidden;        // [B', hidden, h, w] the new hidden state
  torch::Tensor delta_eflow;   // [B', 1, h, w] stage pixels along the epipolar line
  torch::Tensor weight_logit;  // [B', 1, h, w] fusion logit of this pair (softmaxed over sources)
};

class UpdateBlockImpl : public torch::nn::Module {
 public:
  // correlation_channels = levels * samples of the stage's correlation;
  // upsample_factor is the factor of the convex upsampling that follows the
  // stage (its mask has 9 * factor^2 channels).
  // Throws std::invalid_argument on a non-positive size.
  UpdateBlockImpl(int64_t correlation_channels, int64_t hidden_channels,
                  int64_t context_channels, int64_t upsample_factor);

  // hidden [B',hidden,h,w], context [B',context,h,w] (already relu'd),
  // correlation [B',correlation_channels,h,w], eflow [B',1,h,w].
  UpdateBlockOutput forward(const torch::Tensor& hidden, const torch::Tensor& context,
                            const torch::Tensor& correlation, const torch::Tensor& eflow);

  // Convex-upsampling mask logits [B', 9*f*f, h, w] from a hidden state.
  // Scaled by 0.25 as in RAFT, which keeps the mask's gradients in balance
  // with the E-flow head's.
  torch::Tensor MaskLogits(const torch::Tensor& hidden);

  int64_t hidden_channels() const { return hidden_channels_; }
  int64_t upsample_factor() const { return upsample_factor_; }

 private:
  int64_t correlation_channels_;
  int64_t hidden_channels_;
  int64_t context_channels_;
  int64_t upsample_factor_;

  // Motion encoder.
  torch::nn::Conv2d corr_conv1_{nullptr}, corr_conv2_{nullptr};
  torch::nn::Conv2d eflow_conv1_{nullptr}, eflow_conv2_{nullptr};
  torch::nn::Conv2d motion_conv_{nullptr};
  SepConvGru gru_{nullptr};
  // Heads.
  torch::nn::Conv2d head_conv1_{nullptr}, head_conv2_{nullptr};
  torch::nn::Conv2d mask_conv1_{nullptr}, mask_conv2_{nullptr};
};
TORCH_MODULE(UpdateBlock);

// block->forward() on a few pairs at a time: chunks of the batch of at most
// max(1, max_pixels / (h * w)) pairs, outputs concatenated. The pairs are
// independent in the block, so the result is the whole-batch call's (up to
// float rounding), while the block's intermediate maps (hundreds of channels
// per pair) shrink to one chunk's: the inference driver's way to bound
// memory at large image sizes on the CPU (docs/benchmarks.md).
UpdateBlockOutput UpdateInChunks(UpdateBlock& block, const torch::Tensor& hidden,
                                 const torch::Tensor& context, const torch::Tensor& correlation,
                                 const torch::Tensor& eflow, int64_t max_pixels);

// The `max_pixels` DispMvsNet's CPU inference passes (a fine stage of 160x128
// goes through in chunks of 3 pairs, a coarse one in a single call).
inline constexpr int64_t kInferenceUpdatePixelsPerCall = int64_t{1} << 16;

}  // namespace dispmvs::model
