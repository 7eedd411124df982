#pragma once
// Training loss of DispMVS (paper Eq. 14, normalisation Eq. 16; docs/method.md
// section 9): L1 between normalised inverse depths, summed over every
// iteration of both stages.

#include <vector>

#include <torch/torch.h>

namespace dispmvs::model {

// inv_depths: the network's inverse depth after each iteration, in order
// (coarse iterations, then fine), each [B,1,H,W] at the ground truth's
// resolution. gt_depth [B,1,H,W] (metric depth), valid_mask [B,1,H,W] (bool or
// 0/1) marks the pixels with ground truth; d_min, d_max [B] the range hint
// used for normalisation (NormalizeInverseDepth; not clipped).
//
//   loss = sum_i gamma^(n-1-i) * mean_{valid} |norm(1/gt) - norm(inv_depths[i])|
//
// Weights follow RAFT: the LAST iteration has weight 1 and earlier ones decay.
// The paper prints gamma^i, which would weight the random-initialised first
// iteration most; we read that as a typo for RAFT's convention, which the
// paper says it follows.
// The mean is over valid pixels of the whole batch; with no valid pixel the
// loss is 0 (still connected to the graph, so backward() works).
// Throws std::invalid_argument on an empty list, mismatched shapes or
// gamma outside (0, 1].
torch::Tensor SequenceLoss(const std::vector<torch::Tensor>& inv_depths,
                           const torch::Tensor& gt_depth, const torch::Tensor& valid_mask,
                           const torch::Tensor& d_min, const torch::Tensor& d_max,
                           double gamma = 0.9);

}  // namespace dispmvs::model
