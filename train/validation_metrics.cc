#include "train/validation_metrics.h"

#include <stdexcept>
#include <string>

namespace dispmvs::train {

ValidationDepthSums& ValidationDepthSums::operator+=(const ValidationDepthSums& other) {
  gt_pixels += other.gt_pixels;
  covered += other.covered;
  within_1 += other.within_1;
  within_2 += other.within_2;
  within_5 += other.within_5;
  abs_rel_sum += other.abs_rel_sum;
  return *this;
}

namespace {

void CheckSameShape(const torch::Tensor& t, const torch::Tensor& reference, const char* name) {
  if (!t.defined()) throw std::invalid_argument(std::string("depth metrics: ") + name + " is undefined");
  if (t.sizes() != reference.sizes()) {
    throw std::invalid_argument(std::string("depth metrics: ") + name + " has shape " +
                                c10::str(t.sizes()) + ", expected " + c10::str(reference.sizes()));
  }
}

}  // namespace

ValidationDepthSums SumValidationDepth(const torch::Tensor& pred_depth, const torch::Tensor& pred_valid,
                                       const torch::Tensor& gt_depth, const torch::Tensor& gt_valid) {
  if (!gt_depth.defined() || gt_depth.dim() != 4 || gt_depth.size(1) != 1) {
    throw std::invalid_argument("depth metrics: gt_depth must be [B,1,H,W]");
  }
  CheckSameShape(gt_valid, gt_depth, "gt_valid");
  CheckSameShape(pred_depth, gt_depth, "pred_depth");
  CheckSameShape(pred_valid, gt_depth, "pred_valid");

  // Double on the CPU: the sums are exact counts and the relative errors do
  // not lose digits to the float accumulation over many pixels.
  const auto gt = gt_depth.detach().to(torch::kCPU, torch::kDouble);
  const auto pred = pred_depth.detach().to(torch::kCPU, torch::kDouble);
  const auto has_gt = gt_valid.detach().to(torch::kCPU).to(torch::kBool) & (gt > 0) & torch::isfinite(gt);
  const auto has_pred = pred_valid.detach().to(torch::kCPU).to(torch::kBool) & (pred > 0) &
                        torch::isfinite(pred) & has_gt;

  // Missing predictions: relative error 1, i.e. a prediction of 0.
  const auto safe_gt = torch::where(has_gt, gt, torch::ones_like(gt));
  const auto rel = torch::where(has_pred, (pred - gt).abs() / safe_gt, torch::ones_like(gt));

  ValidationDepthSums sums;
  sums.gt_pixels = has_gt.sum().item<int64_t>();
  sums.covered = has_pred.sum().item<int64_t>();
  sums.within_1 = (has_pred & (rel < 0.01)).sum().item<int64_t>();
  sums.within_2 = (has_pred & (rel < 0.02)).sum().item<int64_t>();
  sums.within_5 = (has_pred & (rel < 0.05)).sum().item<int64_t>();
  sums.abs_rel_sum = rel.masked_select(has_gt).sum().item<double>();
  return sums;
}

ValidationDepthMetrics FinalizeValidation(const ValidationDepthSums& sums) {
  ValidationDepthMetrics m;
  m.gt_pixels = sums.gt_pixels;
  if (sums.gt_pixels == 0) return m;
  const double n = static_cast<double>(sums.gt_pixels);
  m.within_1 = sums.within_1 / n;
  m.within_2 = sums.within_2 / n;
  m.within_5 = sums.within_5 / n;
  m.abs_rel = sums.abs_rel_sum / n;
  m.coverage = sums.covered / n;
  return m;
}

}  // namespace dispmvs::train
