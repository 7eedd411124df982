#pragma once
// Pixel-index coordinates for torch::grid_sample, shared by every sampler of
// model/ (epipolar correlation, segment volume, ground-truth depth reads).

#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::model {

// Pixel-index coordinate (pixel i has its centre at i) -> grid_sample
// coordinate for align_corners = false: (2 p + 1) / size - 1.
// align_corners = false is used rather than true because the latter cannot
// address a map of size 1, which coarse pooled levels of small images reach.
// Non-finite or far-away coordinates are moved to +-3, more than one pixel
// outside any map, so they read exactly 0 with zero padding and never reach
// grid_sample's integer conversion as NaN or overflow.
torch::Tensor ToGridCoordinate(const torch::Tensor& pixel, int64_t size);

}  // namespace dispmvs::model
