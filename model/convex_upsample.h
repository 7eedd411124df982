#pragma once
// RAFT's convex upsampling: every fine pixel is a convex combination of the
// 3x3 coarse neighbourhood of its coarse pixel, with weights from a predicted
// mask (softmax over the 9 neighbours).

#include <torch/torch.h>

namespace dispmvs::model {

// x [B,C,H,W], mask_logits [B, 9*factor*factor, H, W] (channel index
// k*factor*factor + i*factor + j holds neighbour k, row-major over the 3x3
// window, for sub-pixel (i, j)) -> [B, C, factor*H, factor*W].
// The border is handled by replicating x (not zero padding) so that a constant
// field stays constant; see convex_upsample.cc.
// Throws std::invalid_argument on mismatched shapes or factor < 1.
torch::Tensor ConvexUpsample(const torch::Tensor& x, const torch::Tensor& mask_logits,
                             int64_t factor);

}  // namespace dispmvs::model
