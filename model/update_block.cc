#include "model/update_block.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

namespace dispmvs::model {
namespace {

namespace nn = torch::nn;

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

SepConvGruImpl::SepConvGruImpl(int64_t hidden_channels, int64_t input_channels) {
  const int64_t in = hidden_channels + input_channels;
  convz1_ = register_module("convz1", Conv(in, hidden_channels, 1, 5));
  convr1_ = register_module("convr1", Conv(in, hidden_channels, 1, 5));
  convq1_ = register_module("convq1", Conv(in, hidden_channels, 1, 5));
  convz2_ = register_module("convz2", Conv(in, hidden_channels, 5, 1));
  convr2_ = register_module("convr2", Conv(in, hidden_channels, 5, 1));
  convq2_ = register_module("convq2", Conv(in, hidden_channels, 5, 1));
}

torch::Tensor SepConvGruImpl::Step(const torch::Tensor& hidden, const torch::Tensor& input,
                                   nn::Conv2d& convz, nn::Conv2d& convr, nn::Conv2d& convq) {
  const torch::Tensor hx = torch::cat({hidden, input}, 1);
  const torch::Tensor z = torch::sigmoid(convz->forward(hx));
  const torch::Tensor r = torch::sigmoid(convr->forward(hx));
  const torch::Tensor q = torch::tanh(convq->forward(torch::cat({r * hidden, input}, 1)));
  return (1 - z) * hidden + z * q;
}

torch::Tensor SepConvGruImpl::forward(torch::Tensor hidden, const torch::Tensor& input) {
  hidden = Step(hidden, input, convz1_, convr1_, convq1_);
  return Step(hidden, input, convz2_, convr2_, convq2_);
}

UpdateBlockImpl::UpdateBlockImpl(int64_t correlation_channels, int64_t hidden_channels,
                                 int64_t context_channels, int64_t upsample_factor)
    : correlation_channels_(correlation_channels),
      hidden_channels_(hidden_channels),
      context_channels_(context_channels),
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
  gru_ = register_module("gru", SepConvGru(hid, hid + context_channels));
  head_conv1_ = register_module("head_conv1", Conv(hid, 2 * hid, 3));
  head_conv2_ = register_module("head_conv2", Conv(2 * hid, 2, 3));
  mask_conv1_ = register_module("mask_conv1", Conv(hid, 2 * hid, 3));
  mask_conv2_ =
      register_module("mask_conv2", Conv(2 * hid, 9 * upsample_factor * upsample_factor, 1));
}

UpdateBlockOutput UpdateBlockImpl::forward(const torch::Tensor& hidden,
                                           const torch::Tensor& context,
                                           const torch::Tensor& correlation,
                                           const torch::Tensor& eflow) {
  if (!hidden.defined() || hidden.dim() != 4) {
    throw std::invalid_argument("UpdateBlock: hidden must be [B,C,h,w]");
  }
  const int64_t batch = hidden.size(0);
  const int64_t h = hidden.size(2);
  const int64_t w = hidden.size(3);
  CheckInput(hidden, "hidden", batch, hidden_channels_, h, w);
  CheckInput(context, "context", batch, context_channels_, h, w);
  CheckInput(correlation, "correlation", batch, correlation_channels_, h, w);
  CheckInput(eflow, "eflow", batch, 1, h, w);

  torch::Tensor corr = torch::relu(corr_conv1_->forward(correlation));
  corr = torch::relu(corr_conv2_->forward(corr));
  torch::Tensor flow = torch::relu(eflow_conv1_->forward(eflow));
  flow = torch::relu(eflow_conv2_->forward(flow));
  const torch::Tensor motion =
      torch::cat({torch::relu(motion_conv_->forward(torch::cat({corr, flow}, 1))), eflow}, 1);

  UpdateBlockOutput out;
  out.hidden = gru_->forward(hidden, torch::cat({motion, context}, 1));
  const torch::Tensor heads =
      head_conv2_->forward(torch::relu(head_conv1_->forward(out.hidden)));
  out.delta_eflow = heads.narrow(1, 0, 1);
  out.weight_logit = heads.narrow(1, 1, 1);
  return out;
}

UpdateBlockOutput UpdateInChunks(UpdateBlock& block, const torch::Tensor& hidden,
                                 const torch::Tensor& context, const torch::Tensor& correlation,
                                 const torch::Tensor& eflow, int64_t max_pixels) {
  if (!hidden.defined() || hidden.dim() != 4) {
    throw std::invalid_argument("UpdateInChunks: hidden must be [B,C,h,w]");
  }
  const int64_t pairs = hidden.size(0);
  const int64_t pixels = std::max<int64_t>(hidden.size(2) * hidden.size(3), 1);
  const int64_t chunk = std::max<int64_t>(1, max_pixels / pixels);
  if (chunk >= pairs) return block->forward(hidden, context, correlation, eflow);
  std::vector<torch::Tensor> hiddens, deltas, logits;
  for (int64_t start = 0; start < pairs; start += chunk) {
    const int64_t n = std::min(chunk, pairs - start);
    const UpdateBlockOutput part =
        block->forward(hidden.narrow(0, start, n), context.narrow(0, start, n),
                       correlation.narrow(0, start, n), eflow.narrow(0, start, n));
    hiddens.push_back(part.hidden);
    deltas.push_back(part.delta_eflow);
    logits.push_back(part.weight_logit);
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
  return 0.25 * mask_conv2_->forward(torch::relu(mask_conv1_->forward(hidden)));
}

}  // namespace dispmvs::model
