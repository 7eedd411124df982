#include "model/correlation.h"

#include <stdexcept>
#include <string>

#include "model/correlation_cpu.h"
#include "model/grid_coordinates.h"

namespace dispmvs::model {
namespace {

namespace F = torch::nn::functional;

void CheckShape(const torch::Tensor& t, const char* name, int64_t batch, int64_t channels,
                int64_t height, int64_t width) {
  if (!t.defined() || t.dim() != 4 || t.size(0) != batch || t.size(1) != channels ||
      t.size(2) != height || t.size(3) != width) {
    throw std::invalid_argument(std::string("EpipolarCorrelation::Lookup: ") + name +
                                " must be [" + std::to_string(batch) + "," +
                                std::to_string(channels) + "," + std::to_string(height) + "," +
                                std::to_string(width) + "], got " +
                                (t.defined() ? c10::str(t.sizes()) : std::string("undefined")));
  }
}

}  // namespace

EpipolarCorrelation::EpipolarCorrelation(const torch::Tensor& source_features, int64_t levels,
                                         int64_t samples, CorrelationImpl impl)
    : samples_(samples) {
  if (!source_features.defined() || source_features.dim() != 4 || source_features.size(0) < 1 ||
      source_features.size(1) < 1 || source_features.size(2) < 1 || source_features.size(3) < 1) {
    throw std::invalid_argument(
        "EpipolarCorrelation: source_features must be a non-empty [B,C,H,W] tensor, got " +
        (source_features.defined() ? c10::str(source_features.sizes()) : std::string("undefined")));
  }
  if (levels < 1 || levels > 16) {
    throw std::invalid_argument("EpipolarCorrelation: levels must be in [1,16], got " +
                                std::to_string(levels));
  }
  if (samples < 1 || samples > 1024) {
    throw std::invalid_argument("EpipolarCorrelation: samples must be in [1,1024], got " +
                                std::to_string(samples));
  }
  pyramid_.reserve(static_cast<size_t>(levels));
  pyramid_.push_back(source_features);
  for (int64_t l = 1; l < levels; ++l) {
    pyramid_.push_back(F::avg_pool2d(pyramid_.back(),
                                     F::AvgPool2dFuncOptions(2).stride(2).ceil_mode(true)));
  }
  // The fused lookup of correlation_cpu.h reads channels-last copies of the
  // levels.
  if (impl == CorrelationImpl::kAuto && FusedCorrelationTakes(source_features)) {
    for (const torch::Tensor& level : pyramid_) {
      levels_hwc_.push_back(level.permute({0, 2, 3, 1}).contiguous());
    }
  }
}

CorrelationSamples EpipolarCorrelation::Lookup(const torch::Tensor& ref_features,
                                               const torch::Tensor& base_xy,
                                               const torch::Tensor& dir,
                                               const torch::Tensor& eflow) const {
  const torch::Tensor& src0 = pyramid_.front();
  const int64_t batch = src0.size(0);
  const int64_t channels = src0.size(1);
  if (!ref_features.defined() || ref_features.dim() != 4) {
    throw std::invalid_argument("EpipolarCorrelation::Lookup: ref_features must be [B,C,h,w]");
  }
  const int64_t h = ref_features.size(2);
  const int64_t w = ref_features.size(3);
  CheckShape(ref_features, "ref_features", batch, channels, h, w);
  CheckShape(base_xy, "base_xy", batch, 2, h, w);
  CheckShape(dir, "dir", batch, 2, h, w);
  CheckShape(eflow, "eflow", batch, 1, h, w);

  // Current match in stage pixels, [B,2,h,w].
  const torch::Tensor match = base_xy + dir * eflow;
  const torch::Tensor offsets =
      (torch::arange(samples_, ref_features.options()) - 0.5 * static_cast<double>(samples_ - 1))
          .view({1, samples_, 1, 1});
  const torch::Tensor dir_x = dir.narrow(1, 0, 1);
  const torch::Tensor dir_y = dir.narrow(1, 1, 1);

  // One sample at a time: sampling all of a level's samples at once holds
  // [B, C, samples, h, w] floats twice (the samples and their products with
  // the reference), 1.1 GB at the fine stage of 1600x1152 with 5 sources;
  // one at a time holds a samples-th of it, for the same arithmetic.
  const bool fused =
      !levels_hwc_.empty() && CanUseFusedCorrelation(src0, ref_features, match, dir);
  std::vector<torch::Tensor> costs;
  std::vector<torch::Tensor> insides;
  costs.reserve(pyramid_.size() * static_cast<size_t>(samples_));
  for (size_t l = 0; l < pyramid_.size(); ++l) {
    const torch::Tensor& source = pyramid_[l];
    const int64_t height_l = source.size(2);
    const int64_t width_l = source.size(3);
    const double scale = static_cast<double>(int64_t{1} << l);
    // Match in level-l pixel coordinates, then the samples along the line.
    const torch::Tensor centre = (match + 0.5) / scale - 0.5;
    const torch::Tensor px = centre.narrow(1, 0, 1) + offsets * dir_x;  // [B,P,h,w]
    const torch::Tensor py = centre.narrow(1, 1, 1) + offsets * dir_y;
    insides.push_back((px >= 0) & (px <= static_cast<double>(width_l - 1)) & (py >= 0) &
                      (py <= static_cast<double>(height_l - 1)));
    if (fused) continue;
    const torch::Tensor grid =
        torch::stack({ToGridCoordinate(px, width_l), ToGridCoordinate(py, height_l)}, -1);
    for (int64_t k = 0; k < samples_; ++k) {
      const torch::Tensor sampled =
          F::grid_sample(source, grid.select(1, k),  // [B,h,w,2] -> [B,C,h,w]
                         F::GridSampleFuncOptions()
                             .mode(torch::kBilinear)
                             .padding_mode(torch::kZeros)
                             .align_corners(false));
      costs.push_back((sampled * ref_features).sum(1, /*keepdim=*/true) /
                      static_cast<double>(channels));
    }
  }
  const torch::Tensor cost =
      fused ? FusedCorrelationLookup(levels_hwc_, ref_features, match, dir, samples_)
            : torch::cat(costs, 1);
  return {cost, torch::cat(insides, 1)};
}

}  // namespace dispmvs::model
