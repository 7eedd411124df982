#pragma once
// Training losses on the network's depth, summed over every iteration of
// both stages with RAFT's decaying weights:
//  * SequenceLoss, the paper's (Eq. 14, normalisation Eq. 16; docs/method.md
//    section 9): L1 between range-normalised inverse depths;
//  * LogDepthSequenceLoss: L1 between log depths, i.e. the relative depth
//    error, the quantity the < 1 / 2 / 5 % metrics threshold.
// Why both: the paper's loss weighs a relative error e at depth d as
// e * d_min / d, so in a scene spanning [0.2, 8.6] a 2 % error at the far end
// counts about 40 times less than at the near end; the far third of the
// validation pixels is where the depth is least precise (docs/training.md,
// "Per iteration, by texture, by depth"). The log loss weighs every pixel's
// relative error alike and needs no range at all.

#include <string>
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

// Which depth loss dispmvs_train minimises (--depth_loss).
enum class DepthLoss { kNormalizedInverse, kLog };
// "inverse" / "log", and back (std::invalid_argument on other text).
const char* DepthLossName(DepthLoss loss);
DepthLoss ParseDepthLoss(const std::string& text);

// Same inputs and weights as SequenceLoss, without the range:
//
//   loss = sum_i gamma^(n-1-i) * mean_{valid} |log(inv_depths[i] * gt)|
//
// (= |log depth_i - log gt|). A pixel whose prediction is not a positive
// finite inverse depth (the network's 0 for "no valid triangulation") adds
// kLogLossCap, a constant without gradient, so that failing to triangulate
// never lowers the loss; a prediction's term is capped there too (a factor of
// e^kLogLossCap away), which keeps a few wild outliers from dominating a
// batch. Throws as SequenceLoss does.
constexpr double kLogLossCap = 2.0;
torch::Tensor LogDepthSequenceLoss(const std::vector<torch::Tensor>& inv_depths,
                                   const torch::Tensor& gt_depth, const torch::Tensor& valid_mask,
                                   double gamma = 0.9);

}  // namespace dispmvs::model
