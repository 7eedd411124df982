#include "model/loss.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "model/geometry.h"

namespace dispmvs::model {

torch::Tensor SequenceLoss(const std::vector<torch::Tensor>& inv_depths,
                           const torch::Tensor& gt_depth, const torch::Tensor& valid_mask,
                           const torch::Tensor& d_min, const torch::Tensor& d_max,
                           double gamma) {
  if (inv_depths.empty()) {
    throw std::invalid_argument("SequenceLoss: inv_depths is empty");
  }
  if (!(gamma > 0.0 && gamma <= 1.0)) {
    throw std::invalid_argument("SequenceLoss: gamma must be in (0, 1], got " +
                                std::to_string(gamma));
  }
  if (!gt_depth.defined() || gt_depth.dim() != 4 || gt_depth.size(1) != 1) {
    throw std::invalid_argument("SequenceLoss: gt_depth must be [B,1,H,W]");
  }
  if (!valid_mask.defined() || valid_mask.sizes() != gt_depth.sizes()) {
    throw std::invalid_argument("SequenceLoss: valid_mask must have gt_depth's shape");
  }
  const int64_t batch = gt_depth.size(0);
  if (!d_min.defined() || !d_max.defined() || d_min.dim() != 1 || d_max.dim() != 1 ||
      d_min.size(0) != batch || d_max.size(0) != batch) {
    throw std::invalid_argument("SequenceLoss: d_min and d_max must be [B]");
  }
  for (size_t i = 0; i < inv_depths.size(); ++i) {
    if (!inv_depths[i].defined() || inv_depths[i].sizes() != gt_depth.sizes()) {
      throw std::invalid_argument("SequenceLoss: inv_depths[" + std::to_string(i) +
                                  "] must have gt_depth's shape");
    }
  }

  // Pixels without usable ground truth get a harmless stand-in value, so that
  // neither the loss nor its gradient can pick up a NaN or Inf from them.
  const torch::Tensor valid =
      valid_mask.to(torch::kBool) & (gt_depth > 0) & torch::isfinite(gt_depth);
  const torch::Tensor safe_gt = torch::where(valid, gt_depth, torch::ones_like(gt_depth));
  const torch::Tensor gt_norm = NormalizeInverseDepth(1.0 / safe_gt, d_min, d_max);
  const torch::Tensor valid_f = valid.to(gt_depth.scalar_type());
  const torch::Tensor count = valid_f.sum().clamp_min(1.0);

  const int64_t n = static_cast<int64_t>(inv_depths.size());
  torch::Tensor loss = torch::zeros({}, gt_depth.options());
  for (int64_t i = 0; i < n; ++i) {
    const double weight = std::pow(gamma, static_cast<double>(n - 1 - i));
    const torch::Tensor pred_norm =
        NormalizeInverseDepth(inv_depths[static_cast<size_t>(i)], d_min, d_max);
    const torch::Tensor l1 = ((pred_norm - gt_norm).abs() * valid_f).sum() / count;
    loss = loss + weight * l1;
  }
  return loss;
}

}  // namespace dispmvs::model
