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
  // [B,V,1,H,W] ground-truth depth of every view (the matching loss checks
  // occlusion with the sources'); all zero for a source without one.
  torch::Tensor gt_depths;
};

// Every sample must have the same view count and image size and a usable
// depth range (0 < depth_min < depth_max). `range_widening` x >= 1 turns the
// hint into (depth_min / x, depth_max * x): the robustness protocol, which
// asks how much the result depends on a good range. The hint travels as
// double-precision [B] tensors converted to the images' dtype.
// Throws std::invalid_argument otherwise.
// range_widening 0 gives no hint at all (undefined depth_min / depth_max):
// for networks that need none (ModelConfig::NeedsDepthRange()).
TrainingBatch MakeBatch(const std::vector<synth::SynthSample>& samples, double range_widening = 1.0);

}  // namespace dispmvs::train
