#pragma once
// The mean of every (2r+1) x (2r+1) window of an image, clipped at the
// border (the mean over the part of the window inside the image: what
// avg_pool2d gives with count_include_pad = false), for every channel.
//
// The photometric refinement (photometric_refinement.h) needs four such means
// per source and depth hypothesis. LibTorch's avg_pool2d on the CPU costs
// about (2r+1)^2 additions per pixel and was most of the refinement's time;
// on CPU float tensors this runs running sums instead (a row pass, then a
// column pass: four additions per pixel, whatever r), one image plane per
// task in parallel. Other devices and types take a sum of shifted slices.

#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::model {

// x: [B,C,H,W], any H, W >= 1; radius >= 0. Returns [B,C,H,W] of x's dtype.
// Throws std::invalid_argument otherwise.
torch::Tensor WindowMean(const torch::Tensor& x, int64_t radius);

}  // namespace dispmvs::model
