#include "train/batch.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace dispmvs::train {

TrainingBatch MakeBatch(const std::vector<synth::SynthSample>& samples, double range_widening) {
  if (samples.empty()) throw std::invalid_argument("MakeBatch: no samples");
  if (!std::isfinite(range_widening) || (range_widening < 1.0 && range_widening != 0.0)) {
    throw std::invalid_argument("MakeBatch: range widening must be 0 (no hint) or a finite number >= 1, got " +
                                std::to_string(range_widening));
  }
  const auto& first = samples.front();
  std::vector<torch::Tensor> images, intrinsics, extrinsics, depths, all_depths;
  std::vector<double> d_min, d_max;
  for (size_t i = 0; i < samples.size(); ++i) {
    const auto& s = samples[i];
    if (!s.images.defined() || s.images.sizes() != first.images.sizes() ||
        s.depths.sizes() != first.depths.sizes()) {
      throw std::invalid_argument("MakeBatch: sample " + std::to_string(i) +
                                  " differs in view count or image size from sample 0");
    }
    if (!(s.depth_min > 0 && s.depth_min < s.depth_max && std::isfinite(s.depth_max))) {
      throw std::invalid_argument("MakeBatch: sample " + std::to_string(i) +
                                  " has no usable depth range (" + std::to_string(s.depth_min) +
                                  ", " + std::to_string(s.depth_max) + ")");
    }
    images.push_back(s.images);
    intrinsics.push_back(s.intrinsics);
    extrinsics.push_back(s.world_to_camera);
    depths.push_back(s.depths.select(0, 0));  // reference view: [1,H,W]
    all_depths.push_back(s.depths);
    d_min.push_back(s.depth_min / range_widening);
    d_max.push_back(s.depth_max * range_widening);
  }
  const auto range_options = torch::TensorOptions().dtype(torch::kDouble);
  TrainingBatch batch;
  batch.input.images = torch::stack(images);
  batch.input.intrinsics = torch::stack(intrinsics);
  batch.input.extrinsics = torch::stack(extrinsics);
  if (range_widening != 0.0) {
    batch.input.depth_min = torch::tensor(d_min, range_options)
                                .to(first.images.device(), first.images.scalar_type());
    batch.input.depth_max = torch::tensor(d_max, range_options)
                                .to(first.images.device(), first.images.scalar_type());
  }
  batch.gt_depth = torch::stack(depths);
  batch.gt_valid = batch.gt_depth > 0;
  batch.gt_depths = torch::stack(all_depths);
  return batch;
}

}  // namespace dispmvs::train
