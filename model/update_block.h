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

#include "model/precision.h"

namespace dispmvs::model {

// GRU whose gates are two separable convolutions: first 1x5 (horizontal
// context), then 5x1 (vertical), each a full GRU step (paper Eq. 17, in the
// supplement; docs/method.md section 7). Its input is [motion, context].
//
// The context is the same for every source view and every iteration of a
// stage, so its share of the six gate convolutions (a third of their
// multiply-adds in the shipped configurations) is computed once per
// reference and stage by ContextTerms() and added to each pair's
// convolution of [hidden, motion]. That is the convolution over the whole
// concatenation [hidden, motion, context], its sums taken in another order:
// equal up to float rounding, same weights, same parameter names.
class SepConvGruImpl : public torch::nn::Module {
 public:
  SepConvGruImpl(int64_t hidden_channels, int64_t motion_channels, int64_t context_channels);

  // context [R, context, h, w] -> [R, 6*hidden, h, w]: the context's share
  // of the gates z, r, q of the 1x5 pass, then of the 5x1 pass, biases
  // included.
  torch::Tensor ContextTerms(const torch::Tensor& context);

  // hidden [B', hidden, h, w], motion [B', motion, h, w], context_terms
  // [R, 6*hidden, h, w] from ContextTerms(), with B' a multiple of R: pairs
  // r*(B'/R) ... (r+1)*(B'/R)-1 share the context of reference r.
  torch::Tensor forward(torch::Tensor hidden, const torch::Tensor& motion,
                        const torch::Tensor& context_terms);

  // forward() for inference (autograd off), with less memory traffic: the
  // caller gives the gate convolutions' input as one buffer
  // [B', hidden + motion, h, w] in the convolutions' dtype (bf16 or fp32,
  // see precision()) with the motion already in channels hidden.. ; the
  // hidden part is scratch. The element-wise gate arithmetic runs in the
  // state's dtype: on the CPU in the two fused passes of gru_gates_cpu.h,
  // elsewhere in place with ATen ops. Same values as forward() up to float
  // rounding (update_block_test).
  torch::Tensor ForwardInPlace(torch::Tensor hidden, torch::Tensor& gate_input,
                               const torch::Tensor& context_terms);

  // The arithmetic of the gate convolutions (precision.h); fp32 by default.
  void set_precision(Precision precision) { precision_ = precision; }
  Precision precision() const { return precision_; }

 private:
  torch::Tensor Step(const torch::Tensor& hidden, const torch::Tensor& motion,
                     const torch::Tensor& terms, torch::nn::Conv2d& convz,
                     torch::nn::Conv2d& convr, torch::nn::Conv2d& convq);
  torch::Tensor StepInPlace(const torch::Tensor& hidden, torch::Tensor& gate_input,
                            const torch::Tensor& terms, torch::nn::Conv2d& convz,
                            torch::nn::Conv2d& convr, torch::nn::Conv2d& convq);
  void CheckForwardInput(const torch::Tensor& hidden, const torch::Tensor& motion,
                         const torch::Tensor& context_terms) const;

  int64_t hidden_channels_;
  int64_t motion_channels_;
  int64_t context_channels_;
  Precision precision_ = Precision::kFloat32;
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

  // The context's share of the GRU gates, [R, 6*hidden, h, w], from the
  // references' context [R, context_channels, h, w] (already relu'd):
  // computed once per stage and passed to every forward() of the stage.
  torch::Tensor ContextTerms(const torch::Tensor& context);

  // hidden [B',hidden,h,w], context_terms [R,6*hidden,h,w] from
  // ContextTerms() with B' a multiple of R (pairs r*(B'/R) ... of reference
  // r, as the driver folds sources into the batch), correlation
  // [B',correlation_channels,h,w], eflow [B',1,h,w].
  UpdateBlockOutput forward(const torch::Tensor& hidden, const torch::Tensor& context_terms,
                            const torch::Tensor& correlation, const torch::Tensor& eflow);

  // Convex-upsampling mask logits [B', 9*f*f, h, w] from a hidden state.
  // Scaled by 0.25 as in RAFT, which keeps the mask's gradients in balance
  // with the E-flow head's.
  torch::Tensor MaskLogits(const torch::Tensor& hidden);

  int64_t hidden_channels() const { return hidden_channels_; }
  int64_t upsample_factor() const { return upsample_factor_; }

  // The arithmetic of every convolution of the block, the GRU's included
  // (precision.h): fp32 by default. Inference only: the trainer keeps fp32.
  void set_precision(Precision precision);
  Precision precision() const { return gru_->precision(); }

 private:
  int64_t correlation_channels_;
  int64_t hidden_channels_;
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

// block->forward() on a few pairs at a time: chunks of at most
// max(1, max_pixels / (h * w)) pairs of one reference each, outputs
// concatenated. The pairs are independent in the block, so the result is the
// whole-batch call's (up to float rounding), while the block's intermediate
// maps (hundreds of channels per pair) shrink to one chunk's: the inference
// driver's way to bound memory at large image sizes on the CPU
// (docs/benchmarks.md).
UpdateBlockOutput UpdateInChunks(UpdateBlock& block, const torch::Tensor& hidden,
                                 const torch::Tensor& context_terms,
                                 const torch::Tensor& correlation,
                                 const torch::Tensor& eflow, int64_t max_pixels);

// The `max_pixels` DispMvsNet's CPU inference passes (a fine stage of 160x128
// goes through in chunks of 3 pairs, a coarse one in a single call).
inline constexpr int64_t kInferenceUpdatePixelsPerCall = int64_t{1} << 16;

}  // namespace dispmvs::model
