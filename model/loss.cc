#include "model/loss.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "model/geometry.h"

namespace dispmvs::model {

namespace {

// Throws std::invalid_argument (messages prefixed by `who`) unless the
// inputs have the shapes the sequence losses take.
void CheckSequenceInputs(const char* who, const std::vector<torch::Tensor>& inv_depths,
                         const torch::Tensor& gt_depth, const torch::Tensor& valid_mask, double gamma) {
  const std::string name = who;
  if (inv_depths.empty()) {
    throw std::invalid_argument(name + ": inv_depths is empty");
  }
  if (!(gamma > 0.0 && gamma <= 1.0)) {
    throw std::invalid_argument(name + ": gamma must be in (0, 1], got " + std::to_string(gamma));
  }
  if (!gt_depth.defined() || gt_depth.dim() != 4 || gt_depth.size(1) != 1) {
    throw std::invalid_argument(name + ": gt_depth must be [B,1,H,W]");
  }
  if (!valid_mask.defined() || valid_mask.sizes() != gt_depth.sizes()) {
    throw std::invalid_argument(name + ": valid_mask must have gt_depth's shape");
  }
  for (size_t i = 0; i < inv_depths.size(); ++i) {
    if (!inv_depths[i].defined() || inv_depths[i].sizes() != gt_depth.sizes()) {
      throw std::invalid_argument(name + ": inv_depths[" + std::to_string(i) +
                                  "] must have gt_depth's shape");
    }
  }
}

// The pixels with usable ground truth, and the ground truth with a harmless
// stand-in (1) elsewhere, so that neither a loss nor its gradient can pick up
// a NaN or Inf from them.
struct UsableGroundTruth {
  torch::Tensor valid;    // bool
  torch::Tensor valid_f;  // 0/1 in gt_depth's type
  torch::Tensor count;    // number of valid pixels, at least 1
  torch::Tensor depth;
};

UsableGroundTruth Usable(const torch::Tensor& gt_depth, const torch::Tensor& valid_mask) {
  UsableGroundTruth gt;
  gt.valid = valid_mask.to(torch::kBool) & (gt_depth > 0) & torch::isfinite(gt_depth);
  gt.depth = torch::where(gt.valid, gt_depth, torch::ones_like(gt_depth));
  gt.valid_f = gt.valid.to(gt_depth.scalar_type());
  gt.count = gt.valid_f.sum().clamp_min(1.0);
  return gt;
}

// sum_i gamma^(n-1-i) * per_iteration(i): the last iteration has weight 1.
template <typename PerIteration>
torch::Tensor DecayingSum(int64_t n, double gamma, const torch::Tensor& zero, PerIteration per_iteration) {
  torch::Tensor loss = zero;
  for (int64_t i = 0; i < n; ++i) {
    loss = loss + std::pow(gamma, static_cast<double>(n - 1 - i)) * per_iteration(static_cast<size_t>(i));
  }
  return loss;
}

}  // namespace

torch::Tensor SequenceLoss(const std::vector<torch::Tensor>& inv_depths,
                           const torch::Tensor& gt_depth, const torch::Tensor& valid_mask,
                           const torch::Tensor& d_min, const torch::Tensor& d_max,
                           double gamma) {
  CheckSequenceInputs("SequenceLoss", inv_depths, gt_depth, valid_mask, gamma);
  const int64_t batch = gt_depth.size(0);
  if (!d_min.defined() || !d_max.defined() || d_min.dim() != 1 || d_max.dim() != 1 ||
      d_min.size(0) != batch || d_max.size(0) != batch) {
    throw std::invalid_argument("SequenceLoss: d_min and d_max must be [B]");
  }
  const UsableGroundTruth gt = Usable(gt_depth, valid_mask);
  const torch::Tensor gt_norm = NormalizeInverseDepth(1.0 / gt.depth, d_min, d_max);
  return DecayingSum(static_cast<int64_t>(inv_depths.size()), gamma, torch::zeros({}, gt_depth.options()),
                     [&](size_t i) {
                       const torch::Tensor pred_norm = NormalizeInverseDepth(inv_depths[i], d_min, d_max);
                       return ((pred_norm - gt_norm).abs() * gt.valid_f).sum() / gt.count;
                     });
}

torch::Tensor LogDepthSequenceLoss(const std::vector<torch::Tensor>& inv_depths,
                                   const torch::Tensor& gt_depth, const torch::Tensor& valid_mask,
                                   double gamma) {
  CheckSequenceInputs("LogDepthSequenceLoss", inv_depths, gt_depth, valid_mask, gamma);
  const UsableGroundTruth gt = Usable(gt_depth, valid_mask);
  return DecayingSum(static_cast<int64_t>(inv_depths.size()), gamma, torch::zeros({}, gt_depth.options()),
                     [&](size_t i) {
                       const torch::Tensor& w = inv_depths[i];
                       const torch::Tensor usable = (w > 0) & torch::isfinite(w);
                       // log(w * gt) = log(gt / depth); the stand-in 1 keeps
                       // log() finite where the prediction is unusable.
                       const torch::Tensor ratio = torch::where(usable, w, torch::ones_like(w)) * gt.depth;
                       const torch::Tensor term = torch::where(
                           usable, ratio.log().abs().clamp_max(kLogLossCap),
                           torch::full_like(w, kLogLossCap));
                       return (term * gt.valid_f).sum() / gt.count;
                     });
}

const char* DepthLossName(DepthLoss loss) {
  return loss == DepthLoss::kLog ? "log" : "inverse";
}

DepthLoss ParseDepthLoss(const std::string& text) {
  if (text == "inverse") return DepthLoss::kNormalizedInverse;
  if (text == "log") return DepthLoss::kLog;
  throw std::invalid_argument("depth loss must be 'inverse' (the paper's) or 'log', got '" + text + "'");
}

}  // namespace dispmvs::model
