#pragma once
// The validation's depth maps seen from the source views: how far the
// network's matches are from the true ones in the sources' pixels, and how
// fine a match the depth thresholds ask for.
//
// A depth threshold means different things at different pixels: where the
// sources see a point under a small angle, 2 % of depth moves its match by a
// fraction of a pixel, and no matcher reaches <2 % there without sub-pixel
// precision. So beside the depth table the validation reports, per
// (reference pixel, source) pair where the source sees the ground-truth
// point (in its frame and not occluded there, model::ComputeGroundTruthMatches
// at full resolution), whether the predicted depth projects within 1 / 2
// source pixels of the true match (the measure bench/motorcycle_check.sh
// applies to a real pair), and per reference pixel some source sees, whether
// a 2 % depth error moves the true match by at least 1 / 0.5 pixels in the
// seeing source where it moves most.

#include <cstdint>
#include <string>

#include <torch/torch.h>

namespace dispmvs::train {

struct SourcePixelCounts {
  int64_t seeing_pairs = 0;      // (pixel, source) pairs where the source sees the point
  int64_t pairs_within_1px = 0;  // ... whose predicted depth projects within 1 px of the truth
  int64_t pairs_within_2px = 0;  // ... within 2 px (a pixel without prediction is neither)
  int64_t seen_pixels = 0;       // reference pixels with ground truth that some source sees
  int64_t moves_1px = 0;         // ... where 2 % of depth moves the match >= 1 px in the best source
  int64_t moves_half_px = 0;     // ... >= 0.5 px

  SourcePixelCounts& operator+=(const SourcePixelCounts& other);
};

// gt_depths [B,V,1,H,W] (view 0 the reference; 0 = no depth; a source whose
// map is all zero is not checked for occlusion), intrinsics [B,V,3,3] in
// the pixel-index convention, extrinsics [B,V,4,4] world-to-camera,
// pred_depth / pred_valid [B,1,H,W] (a prediction counts only where valid,
// finite and positive). The "move" of 2 % is the smaller of those of 2 %
// nearer and 2 % farther. Computed in double precision. `seen` (optional)
// receives the [B,1,H,W] bool mask of the seen pixels.
// Throws std::invalid_argument on mismatched shapes.
SourcePixelCounts CountSourcePixels(const torch::Tensor& gt_depths, const torch::Tensor& intrinsics,
                                    const torch::Tensor& extrinsics, const torch::Tensor& pred_depth,
                                    const torch::Tensor& pred_valid, torch::Tensor* seen = nullptr);

// The counts as shares (0 where the whole is 0).
struct SourcePixelShares {
  double within_1px = 0, within_2px = 0;  // of the seeing pairs
  double moves_1px = 0, moves_half_px = 0;  // of the seen pixels
};
SourcePixelShares SharesOf(const SourcePixelCounts& counts);

// "in the sources' pixels: <1 px: 0.1234  <2 px: ...; 2 % of depth moves the
// match >= 1 px: ...  >= 0.5 px: ...".
std::string FormatSourcePixels(const SourcePixelShares& shares);

}  // namespace dispmvs::train
