#include "model/update_block.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/gru_gates_cpu.h"

namespace dispmvs::model {
namespace {

namespace nn = torch::nn;

// Zero padding that keeps the map size for an odd kernel, as Conv() sets it:
// the functional convolutions of the split GRU use the modules' weights with
// the modules' padding.
std::vector<int64_t> SamePadding(const torch::Tensor& weight) {
  return {weight.size(2) / 2, weight.size(3) / 2};
}

nn::Conv2d Conv(int64_t in, int64_t out, int64_t kernel_h, int64_t kernel_w) {
  return nn::Conv2d(nn::Conv2dOptions(in, out, {kernel_h, kernel_w})
                        .padding({kernel_h / 2, kernel_w / 2}));
}
nn::Conv2d Conv(int64_t in, int64_t out, int64_t kernel) { return Conv(in, out, kernel, kernel); }

void CheckInput(const torch::Tensor& t, const char* name, int64_t batch, int64_t channels,
                int64_t height, int64_t width) {
  if (!t.defined() || t.dim() != 4 || t.size(0) != batch || t.size(1) != channels ||
      t.size(2) != height || t.size(3) != width) {
    throw std::invalid_argument(std::string("UpdateBlock: ") + name + " must be [" +
                                std::to_string(batch) + "," + std::to_string(channels) + "," +
                                std::to_string(height) + "," + std::to_string(width) + "]");
  }
}

}  // namespace

SepConvGruImpl::SepConvGruImpl(int64_t hidden_channels, int64_t motion_channels,
                               int64_t context_channels)
    : hidden_channels_(hidden_channels),
      motion_channels_(motion_channels),
      context_channels_(context_channels) {
  if (hidden_channels < 1 || motion_channels < 1 || context_channels < 1) {
    throw std::invalid_argument("SepConvGru: every channel count must be >= 1");
  }
  const int64_t in = hidden_channels + motion_channels + context_channels;
  convz1_ = register_module("convz1", Conv(in, hidden_channels, 1, 5));
  convr1_ = register_module("convr1", Conv(in, hidden_channels, 1, 5));
  convq1_ = register_module("convq1", Conv(in, hidden_channels, 1, 5));
  convz2_ = register_module("convz2", Conv(in, hidden_channels, 5, 1));
  convr2_ = register_module("convr2", Conv(in, hidden_channels, 5, 1));
  convq2_ = register_module("convq2", Conv(in, hidden_channels, 5, 1));
}

torch::Tensor SepConvGruImpl::ContextTerms(const torch::Tensor& context) {
  if (!context.defined() || context.dim() != 4 || context.size(1) != context_channels_) {
    throw std::invalid_argument("SepConvGru: context must be [R," +
                                std::to_string(context_channels_) + ",h,w]");
  }
  const int64_t first = hidden_channels_ + motion_channels_;
  std::vector<torch::Tensor> passes;
  for (const std::vector<nn::Conv2d*>& pass :
       {std::vector<nn::Conv2d*>{&convz1_, &convr1_, &convq1_},
        std::vector<nn::Conv2d*>{&convz2_, &convr2_, &convq2_}}) {
    // One convolution per pass: the three gates' context columns stacked.
    std::vector<torch::Tensor> weights, biases;
    for (nn::Conv2d* conv : pass) {
      weights.push_back((*conv)->weight.narrow(1, first, context_channels_));
      biases.push_back((*conv)->bias);
    }
    const torch::Tensor weight = torch::cat(weights, 0);
    passes.push_back(
        Conv2dIn(precision_, context, weight, torch::cat(biases, 0), SamePadding(weight)));
  }
  return torch::cat(passes, 1);
}

namespace {

// pre [B', C, h, w] + terms [R, C, h, w] broadcast over each reference's
// B'/R pairs, in place (a convolution's output: autograd does not keep it).
torch::Tensor AddPerReference(torch::Tensor pre, const torch::Tensor& terms) {
  const int64_t refs = terms.size(0);
  pre = pre.contiguous();  // a no-op for the NCHW maps the block makes
  pre.view({refs, pre.size(0) / refs, pre.size(1), pre.size(2), pre.size(3)})
      .add_(terms.unsqueeze(1));
  return pre;
}

// The [hidden, motion] columns of a gate convolution's weight.
torch::Tensor PairColumns(const nn::Conv2d& conv, int64_t columns) {
  return conv->weight.narrow(1, 0, columns);
}

}  // namespace

torch::Tensor SepConvGruImpl::Step(const torch::Tensor& hidden, const torch::Tensor& motion,
                                   const torch::Tensor& terms, nn::Conv2d& convz,
                                   nn::Conv2d& convr, nn::Conv2d& convq) {
  const int64_t hid = hidden_channels_, columns = hidden_channels_ + motion_channels_;
  const std::vector<int64_t> padding = SamePadding(convz->weight);
  // z and r read the same input: one convolution with both weights stacked.
  const torch::Tensor zr_weight =
      torch::cat({PairColumns(convz, columns), PairColumns(convr, columns)}, 0);
  const torch::Tensor zr = torch::sigmoid(AddPerReference(
      Conv2dIn(precision_, torch::cat({hidden, motion}, 1), zr_weight, {}, padding),
      terms.narrow(1, 0, 2 * hid)));
  const torch::Tensor z = zr.narrow(1, 0, hid);
  const torch::Tensor r = zr.narrow(1, hid, hid);
  const torch::Tensor q = torch::tanh(AddPerReference(
      Conv2dIn(precision_, torch::cat({r * hidden, motion}, 1), PairColumns(convq, columns), {},
               padding),
      terms.narrow(1, 2 * hid, hid)));
  return (1 - z) * hidden + z * q;
}

void SepConvGruImpl::CheckForwardInput(const torch::Tensor& hidden, const torch::Tensor& motion,
                                       const torch::Tensor& context_terms) const {
  const int64_t hid = hidden_channels_;
  if (!hidden.defined() || !motion.defined() || !context_terms.defined() || hidden.dim() != 4 ||
      motion.dim() != 4 || context_terms.dim() != 4 || hidden.size(1) != hid ||
      motion.size(1) != motion_channels_ || context_terms.size(1) != 6 * hid ||
      motion.size(0) != hidden.size(0) || context_terms.size(0) < 1 ||
      hidden.size(0) % context_terms.size(0) != 0 ||
      motion.sizes().slice(2) != hidden.sizes().slice(2) ||
      context_terms.sizes().slice(2) != hidden.sizes().slice(2)) {
    throw std::invalid_argument(
        "SepConvGru: need hidden [B'," + std::to_string(hid) + ",h,w], motion [B'," +
        std::to_string(motion_channels_) + ",h,w] and context terms [R," +
        std::to_string(6 * hid) + ",h,w] with B' a multiple of R");
  }
}

torch::Tensor SepConvGruImpl::forward(torch::Tensor hidden, const torch::Tensor& motion,
                                      const torch::Tensor& context_terms) {
  const int64_t hid = hidden_channels_;
  CheckForwardInput(hidden, motion, context_terms);
  hidden = Step(hidden, motion, context_terms.narrow(1, 0, 3 * hid), convz1_, convr1_, convq1_);
  return Step(hidden, motion, context_terms.narrow(1, 3 * hid, 3 * hid), convz2_, convr2_,
              convq2_);
}

torch::Tensor SepConvGruImpl::StepInPlace(const torch::Tensor& hidden, torch::Tensor& gate_input,
                                          const torch::Tensor& terms, nn::Conv2d& convz,
                                          nn::Conv2d& convr, nn::Conv2d& convq) {
  const int64_t hid = hidden_channels_, columns = hidden_channels_ + motion_channels_;
  const std::vector<int64_t> padding = SamePadding(convz->weight);
  torch::Tensor state_part = gate_input.narrow(1, 0, hid);  // a view: writes land in the buffer
  state_part.copy_(hidden);  // rounded to the convolution's dtype, as Step's cat
  const torch::Tensor zr_weight =
      torch::cat({PairColumns(convz, columns), PairColumns(convr, columns)}, 0);
  const torch::Tensor zr_pre =
      Conv2dIn(precision_, gate_input, zr_weight, {}, padding).contiguous();
  const torch::Tensor zr_terms = terms.narrow(1, 0, 2 * hid);
  const torch::Tensor q_terms = terms.narrow(1, 2 * hid, hid);
  const auto q_pre = [&] {
    return Conv2dIn(precision_, gate_input, PairColumns(convq, columns), {}, padding).contiguous();
  };
  if (CanUseFusedGates(zr_pre, hidden)) {
    // The CPU's two fused passes (gru_gates_cpu.h); r * hidden goes
    // straight into the buffer.
    const torch::Tensor z = FusedUpdateAndResetGates(zr_pre, zr_terms, hidden, gate_input);
    return FusedCandidateBlend(q_pre(), q_terms, hidden, z);
  }
  // Elsewhere (a GPU, float64): ATen ops, in place on fp32 copies of the
  // convolution outputs (new tensors when they are bf16).
  const torch::Tensor zr =
      AddPerReference(zr_pre.to(hidden.scalar_type()), zr_terms).sigmoid_();
  const torch::Tensor z = zr.narrow(1, 0, hid);
  torch::mul_out(state_part, zr.narrow(1, hid, hid), hidden);  // r * hidden
  const torch::Tensor q = AddPerReference(q_pre().to(hidden.scalar_type()), q_terms).tanh_();
  return torch::lerp(hidden, q, z);  // (1 - z) hidden + z q
}

torch::Tensor SepConvGruImpl::ForwardInPlace(torch::Tensor hidden, torch::Tensor& gate_input,
                                             const torch::Tensor& context_terms) {
  if (torch::GradMode::is_enabled()) {
    throw std::logic_error("SepConvGru::ForwardInPlace is for inference (autograd off)");
  }
  const int64_t hid = hidden_channels_;
  if (!gate_input.defined() || gate_input.dim() != 4 ||
      gate_input.size(1) != hid + motion_channels_ || !gate_input.is_contiguous()) {
    throw std::invalid_argument("SepConvGru: gate_input must be a contiguous [B'," +
                                std::to_string(hid + motion_channels_) + ",h,w] buffer");
  }
  CheckForwardInput(hidden, gate_input.narrow(1, hid, motion_channels_), context_terms);
  hidden = StepInPlace(hidden.contiguous(), gate_input, context_terms.narrow(1, 0, 3 * hid), convz1_, convr1_,
                       convq1_);
  return StepInPlace(hidden, gate_input, context_terms.narrow(1, 3 * hid, 3 * hid), convz2_,
                     convr2_, convq2_);
}

UpdateBlockImpl::UpdateBlockImpl(int64_t correlation_channels, int64_t hidden_channels,
                                 int64_t context_channels, int64_t upsample_factor)
    : correlation_channels_(correlation_channels),
      hidden_channels_(hidden_channels),
      upsample_factor_(upsample_factor) {
  if (correlation_channels < 1 || hidden_channels < 2 || context_channels < 1 ||
      upsample_factor < 1) {
    throw std::invalid_argument(
        "UpdateBlock: need correlation_channels >= 1, hidden_channels >= 2, "
        "context_channels >= 1, upsample_factor >= 1");
  }
  const int64_t hid = hidden_channels;
  // Correlation branch 2h -> 1.5h, E-flow branch h -> h/2 (RAFT at h = 128).
  const int64_t corr1 = 2 * hid;
  const int64_t corr2 = (3 * hid) / 2;
  const int64_t flow1 = hid;
  const int64_t flow2 = std::max<int64_t>(hid / 2, 1);
  corr_conv1_ = register_module("corr_conv1", Conv(correlation_channels, corr1, 1));
  corr_conv2_ = register_module("corr_conv2", Conv(corr1, corr2, 3));
  eflow_conv1_ = register_module("eflow_conv1", Conv(1, flow1, 7));
  eflow_conv2_ = register_module("eflow_conv2", Conv(flow1, flow2, 3));
  // hid - 1 channels, then the raw E-flow is appended: hid motion channels.
  motion_conv_ = register_module("motion_conv", Conv(corr2 + flow2, hid - 1, 3));
  gru_ = register_module("gru", SepConvGru(hid, hid, context_channels));
  head_conv1_ = register_module("head_conv1", Conv(hid, 2 * hid, 3));
  head_conv2_ = register_module("head_conv2", Conv(2 * hid, 2, 3));
  mask_conv1_ = register_module("mask_conv1", Conv(hid, 2 * hid, 3));
  mask_conv2_ =
      register_module("mask_conv2", Conv(2 * hid, 9 * upsample_factor * upsample_factor, 1));
}

void UpdateBlockImpl::set_precision(Precision precision) {
  gru_->set_precision(precision);
}

torch::Tensor UpdateBlockImpl::ContextTerms(const torch::Tensor& context) {
  return gru_->ContextTerms(context);
}

UpdateBlockOutput UpdateBlockImpl::forward(const torch::Tensor& hidden,
                                           const torch::Tensor& context_terms,
                                           const torch::Tensor& correlation,
                                           const torch::Tensor& eflow) {
  if (!hidden.defined() || hidden.dim() != 4) {
    throw std::invalid_argument("UpdateBlock: hidden must be [B,C,h,w]");
  }
  const int64_t batch = hidden.size(0);
  const int64_t h = hidden.size(2);
  const int64_t w = hidden.size(3);
  CheckInput(hidden, "hidden", batch, hidden_channels_, h, w);
  if (!context_terms.defined() || context_terms.dim() != 4 || context_terms.size(0) < 1 ||
      batch % context_terms.size(0) != 0) {
    throw std::invalid_argument(
        "UpdateBlock: context_terms must be [R,...] with the batch a multiple of R");
  }
  CheckInput(context_terms, "context_terms", context_terms.size(0), 6 * hidden_channels_, h, w);
  CheckInput(correlation, "correlation", batch, correlation_channels_, h, w);
  CheckInput(eflow, "eflow", batch, 1, h, w);

  const Precision p = precision();
  // The motion encoder's and the heads' chains stay in the block's precision
  // from one convolution to the next (relu commutes with the rounding);
  // what leaves them, and the GRU's state, is fp32.
  torch::Tensor corr = torch::relu(Conv2dIn(p, corr_conv1_, InPrecision(p, correlation)));
  corr = torch::relu(Conv2dIn(p, corr_conv2_, corr));
  torch::Tensor flow = torch::relu(Conv2dIn(p, eflow_conv1_, InPrecision(p, eflow)));
  flow = torch::relu(Conv2dIn(p, eflow_conv2_, flow));
  const torch::Tensor motion_features =
      torch::relu(Conv2dIn(p, motion_conv_, torch::cat({corr, flow}, 1)));

  UpdateBlockOutput out;
  if (torch::GradMode::is_enabled()) {
    const torch::Tensor motion =
        torch::cat({motion_features.to(eflow.scalar_type()), eflow}, 1);
    out.hidden = gru_->forward(hidden, motion, context_terms);
  } else {
    // Inference: the gates' input buffer, its motion part (the encoder's
    // hid - 1 channels, then the raw E-flow) written once for both passes.
    const int64_t hid = hidden_channels_;
    const torch::ScalarType gate_dtype =
        p == Precision::kBFloat16 ? torch::kBFloat16 : hidden.scalar_type();
    torch::Tensor gate_input = torch::empty({batch, 2 * hid, h, w}, hidden.options().dtype(gate_dtype));
    gate_input.narrow(1, hid, hid - 1).copy_(motion_features);
    gate_input.narrow(1, 2 * hid - 1, 1).copy_(eflow);
    out.hidden = gru_->ForwardInPlace(hidden, gate_input, context_terms);
  }
  const torch::Tensor heads =
      Conv2dIn(p, head_conv2_, torch::relu(Conv2dIn(p, head_conv1_, InPrecision(p, out.hidden))))
          .to(out.hidden.scalar_type());
  out.delta_eflow = heads.narrow(1, 0, 1);
  out.weight_logit = heads.narrow(1, 1, 1);
  return out;
}

UpdateBlockOutput UpdateInChunks(UpdateBlock& block, const torch::Tensor& hidden,
                                 const torch::Tensor& context_terms,
                                 const torch::Tensor& correlation, const torch::Tensor& eflow,
                                 int64_t max_pixels) {
  if (!hidden.defined() || hidden.dim() != 4 || !context_terms.defined() ||
      context_terms.dim() != 4 || context_terms.size(0) < 1 ||
      hidden.size(0) % context_terms.size(0) != 0) {
    throw std::invalid_argument(
        "UpdateInChunks: hidden must be [B',C,h,w] and context_terms [R,...] with B' a "
        "multiple of R");
  }
  const int64_t pairs = hidden.size(0);
  const int64_t references = context_terms.size(0);
  const int64_t pairs_per_reference = pairs / references;
  const int64_t pixels = std::max<int64_t>(hidden.size(2) * hidden.size(3), 1);
  const int64_t chunk = std::max<int64_t>(1, max_pixels / pixels);
  if (chunk >= pairs) return block->forward(hidden, context_terms, correlation, eflow);
  std::vector<torch::Tensor> hiddens, deltas, logits;
  for (int64_t reference = 0; reference < references; ++reference) {
    const torch::Tensor terms = context_terms.narrow(0, reference, 1);
    for (int64_t offset = 0; offset < pairs_per_reference; offset += chunk) {
      const int64_t start = reference * pairs_per_reference + offset;
      const int64_t n = std::min(chunk, pairs_per_reference - offset);
      const UpdateBlockOutput part =
          block->forward(hidden.narrow(0, start, n), terms, correlation.narrow(0, start, n),
                         eflow.narrow(0, start, n));
      hiddens.push_back(part.hidden);
      deltas.push_back(part.delta_eflow);
      logits.push_back(part.weight_logit);
    }
  }
  UpdateBlockOutput out;
  out.hidden = torch::cat(hiddens, 0);
  out.delta_eflow = torch::cat(deltas, 0);
  out.weight_logit = torch::cat(logits, 0);
  return out;
}

torch::Tensor UpdateBlockImpl::MaskLogits(const torch::Tensor& hidden) {
  if (!hidden.defined() || hidden.dim() != 4 || hidden.size(1) != hidden_channels_) {
    throw std::invalid_argument("UpdateBlock::MaskLogits: hidden must be [B," +
                                std::to_string(hidden_channels_) + ",h,w]");
  }
  const Precision p = precision();
  return 0.25 * Conv2dIn(p, mask_conv2_,
                         torch::relu(Conv2dIn(p, mask_conv1_, InPrecision(p, hidden))))
                    .to(hidden.scalar_type());
}

}  // namespace dispmvs::model
