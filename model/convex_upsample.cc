#include "model/convex_upsample.h"

#include <stdexcept>
#include <string>

namespace dispmvs::model {
namespace F = torch::nn::functional;

torch::Tensor ConvexUpsample(const torch::Tensor& x, const torch::Tensor& mask_logits,
                             int64_t factor) {
  if (factor < 1) {
    throw std::invalid_argument("ConvexUpsample: factor must be >= 1, got " +
                                std::to_string(factor));
  }
  if (x.dim() != 4) {
    throw std::invalid_argument("ConvexUpsample: expected x [B,C,H,W], got " + c10::str(x.sizes()));
  }
  const int64_t batch = x.size(0), channels = x.size(1), height = x.size(2), width = x.size(3);
  const int64_t ff = factor * factor;
  if (mask_logits.dim() != 4 || mask_logits.size(0) != batch || mask_logits.size(1) != 9 * ff ||
      mask_logits.size(2) != height || mask_logits.size(3) != width) {
    throw std::invalid_argument("ConvexUpsample: expected mask_logits [" + std::to_string(batch) +
                                "," + std::to_string(9 * ff) + "," + std::to_string(height) + "," +
                                std::to_string(width) + "], got " + c10::str(mask_logits.sizes()));
  }

  // [B, 1, 9, f, f, H, W]: weights of the 9 neighbours for each sub-pixel.
  const torch::Tensor weights =
      torch::softmax(mask_logits.view({batch, 1, 9, factor, factor, height, width}), /*dim=*/2);

  // The 3x3 neighbourhood of every coarse pixel. RAFT zero-pads here, which is
  // harmless for flow near the border but would pull inverse depth towards 0
  // (a point at infinity) along the image edge. Replicating the border keeps
  // every output a convex combination of real values, so a constant field
  // stays constant up to the border.
  const torch::Tensor padded = F::pad(x, F::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReplicate));
  const torch::Tensor neighbours = F::unfold(padded, F::UnfoldFuncOptions({3, 3}))  // [B, C*9, H*W]
                                       .view({batch, channels, 9, 1, 1, height, width});

  const torch::Tensor up = (weights * neighbours).sum(/*dim=*/2);  // [B, C, f, f, H, W]
  // Interleave: output row = h*f + i, column = w*f + j.
  return up.permute({0, 1, 4, 2, 5, 3}).reshape({batch, channels, factor * height, factor * width});
}

}  // namespace dispmvs::model
