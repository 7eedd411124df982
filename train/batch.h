#pragma once
// Stacks generated samples into one network input plus its ground truth.

#include <vector>

#include <torch/torch.h>

#include "model/dispmvs_net.h"
#include "synth/generator.h"

namespace dispmvs::train {

struct TrainingBatch {
  model::DispMvsInput input;  // on the samples' device
  torch::Tensor gt_depth;     // [B,1,H,W] reference depth, 0 where no surface
  torch::Tensor gt_valid;     // [B,1,H,W] bool, gt_depth > 0
};

// Every sample must have the same view count and image size and a usable
// depth range (0 < depth_min < depth_max). `range_widening` x >= 1 turns the
// hint into (depth_min / x, depth_max * x): the robustness protocol, which
// asks how much the result depends on a good range. The hint travels as
// double-precision [B] tensors converted to the images' dtype.
// Throws std::invalid_argument otherwise.
TrainingBatch MakeBatch(const std::vector<synth::SynthSample>& samples, double range_widening = 1.0);

}  // namespace dispmvs::train
