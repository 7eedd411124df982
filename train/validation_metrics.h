#pragma once
// Depth accuracy of a predicted depth map against ground truth on the
// training's validation scenes: the numbers the training log and
// EvaluateWeights' table print. Not eval::DepthMetrics (eval/depth_metrics.h,
// dispmvs_eval), whose abs_rel is over predicted pixels only.
//
// Every valid ground-truth pixel counts. A pixel the network left without a
// prediction is an error, not excluded: it is never "within" a threshold and
// adds relative error 1 to AbsRel (as a prediction of depth 0 would). So a
// network cannot look accurate by predicting few pixels; `coverage` says how
// many it predicted.

#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::train {

// Sums over pixels; add the sums of several batches, then FinalizeValidation().
struct ValidationDepthSums {
  int64_t gt_pixels = 0;    // valid ground-truth pixels
  int64_t covered = 0;      // ... where the prediction is valid
  int64_t within_1 = 0;     // ... with |pred - gt| / gt < 1 %
  int64_t within_2 = 0;     // ... < 2 %
  int64_t within_5 = 0;     // ... < 5 %
  double abs_rel_sum = 0;   // sum of |pred - gt| / gt (1 where no prediction)

  ValidationDepthSums& operator+=(const ValidationDepthSums& other);
};

// Fractions of the valid ground-truth pixels (all 0 when there are none).
struct ValidationDepthMetrics {
  int64_t gt_pixels = 0;
  double within_1 = 0, within_2 = 0, within_5 = 0;
  // Mean over every valid ground-truth pixel of |pred - gt| / gt, where a
  // pixel without a prediction counts 1 (as a prediction of depth 0 would).
  double abs_rel = 0;
  double coverage = 0;  // share of the valid ground-truth pixels predicted
};

// pred_depth, gt_depth [B,1,H,W] (any float dtype, same device); pred_valid,
// gt_valid [B,1,H,W] bool (or 0/1). A prediction also counts as missing where
// it is not finite or not positive, whatever pred_valid says.
// Throws std::invalid_argument on undefined tensors or mismatched shapes.
ValidationDepthSums SumValidationDepth(const torch::Tensor& pred_depth, const torch::Tensor& pred_valid,
                                       const torch::Tensor& gt_depth, const torch::Tensor& gt_valid);

ValidationDepthMetrics FinalizeValidation(const ValidationDepthSums& sums);

}  // namespace dispmvs::train
