#include "model/segment_correlation.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "model/correlation_cpu.h"
#include "model/grid_coordinates.h"

namespace dispmvs::model {
namespace {

namespace F = torch::nn::functional;

// Samples of the volume built per chunk: bounds the [B,C,chunk,h,w] buffer of
// sampled source features (the rest of the memory is the [B,L,h,w] volume).
constexpr int64_t kChunk = 16;

void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("SegmentCorrelation: " + what);
}

// Linear interpolation of vol [B,L,h,w] along dim 1 at fractional indices
// u [B,S,h,w]; 0 outside [0, L-1] (each neighbour contributes only if it
// exists, like zero padding).
torch::Tensor Interpolate1d(const torch::Tensor& vol, const torch::Tensor& u) {
  const int64_t length = vol.size(1);
  const torch::Tensor safe_u = torch::where(torch::isfinite(u), u, torch::full_like(u, -2.0))
                                   .clamp(-2.0, static_cast<double>(length + 1));
  const torch::Tensor lower = safe_u.floor();
  const torch::Tensor frac = safe_u - lower;
  const torch::Tensor i0 = lower.to(torch::kLong);
  const torch::Tensor i1 = i0 + 1;
  const auto read = [&](const torch::Tensor& i) {
    const torch::Tensor exists = (i >= 0) & (i < length);
    const torch::Tensor value = vol.gather(1, i.clamp(0, length - 1));
    return torch::where(exists, value, torch::zeros_like(value));
  };
  return read(i0) * (1.0 - frac) + read(i1) * frac;
}

// The level-0 volume [B,L,h,w] with ATen ops (autograd w.r.t. everything,
// any device: a GPU, float64, CorrelationImpl::kAtenOps), kChunk samples at
// a time; eflows [B,L,h,w] the samples' E-flows.
torch::Tensor AtenVolume(const torch::Tensor& ref_features, const torch::Tensor& src_features,
                         const EpipolarSegment& segment, const torch::Tensor& eflows) {
  const int64_t batch = src_features.size(0), channels = src_features.size(1);
  const int64_t src_h = src_features.size(2), src_w = src_features.size(3);
  const int64_t h = ref_features.size(2), w = ref_features.size(3);
  const int64_t length = eflows.size(1);
  const torch::Tensor base_x = segment.base_xy.narrow(1, 0, 1);
  const torch::Tensor base_y = segment.base_xy.narrow(1, 1, 1);
  const torch::Tensor dir_x = segment.dir.narrow(1, 0, 1);
  const torch::Tensor dir_y = segment.dir.narrow(1, 1, 1);
  const torch::Tensor ref = ref_features.unsqueeze(2);  // [B,C,1,h,w]
  std::vector<torch::Tensor> chunks;
  for (int64_t k0 = 0; k0 < length; k0 += kChunk) {
    const int64_t n = std::min(kChunk, length - k0);
    const torch::Tensor e = eflows.narrow(1, k0, n);
    const torch::Tensor px = base_x + e * dir_x;
    const torch::Tensor py = base_y + e * dir_y;
    const torch::Tensor grid =
        torch::stack({ToGridCoordinate(px, src_w), ToGridCoordinate(py, src_h)}, -1).view({batch, n * h, w, 2});
    const torch::Tensor sampled =
        F::grid_sample(src_features, grid,
                       F::GridSampleFuncOptions()
                           .mode(torch::kBilinear)
                           .padding_mode(torch::kZeros)
                           .align_corners(false))
            .view({batch, channels, n, h, w});
    chunks.push_back((sampled * ref).sum(1) / static_cast<double>(channels));
  }
  return torch::cat(chunks, 1);
}

}  // namespace

SegmentCorrelation::SegmentCorrelation(const torch::Tensor& ref_features,
                                       const torch::Tensor& src_features,
                                       const EpipolarSegment& segment, int64_t levels,
                                       int64_t samples, CorrelationImpl impl)
    : segment_(segment), samples_(samples) {
  Require(src_features.defined() && src_features.dim() == 4 && src_features.size(0) >= 1 &&
              src_features.size(1) >= 1 && src_features.size(2) >= 1 && src_features.size(3) >= 1,
          "src_features must be a non-empty [B,C,H,W] tensor");
  const int64_t batch = src_features.size(0);
  const int64_t channels = src_features.size(1);
  const int64_t src_h = src_features.size(2);
  const int64_t src_w = src_features.size(3);
  Require(ref_features.defined() && ref_features.dim() == 4 && ref_features.size(0) == batch &&
              ref_features.size(1) == channels,
          "ref_features must be [B,C,h,w] with the sources' B and C");
  const int64_t h = ref_features.size(2);
  const int64_t w = ref_features.size(3);
  const std::vector<int64_t> grid2{batch, 2, h, w}, grid1{batch, 1, h, w};
  Require(segment.base_xy.defined() && segment.base_xy.sizes() == torch::IntArrayRef(grid2) &&
              segment.dir.sizes() == torch::IntArrayRef(grid2) &&
              segment.start.sizes() == torch::IntArrayRef(grid1) &&
              segment.end.sizes() == torch::IntArrayRef(grid1) &&
              segment.valid.sizes() == torch::IntArrayRef(grid1),
          "segment tensors must be [B,2,h,w] / [B,1,h,w] on the reference grid");
  Require(levels >= 1 && levels <= 16, "levels must be in [1,16], got " + std::to_string(levels));
  Require(samples >= 1 && samples <= 1024,
          "samples must be in [1,1024], got " + std::to_string(samples));
  feature_channels_ = channels;

  // L: the longest segment (+1 for both ends), never longer than the source
  // diagonal allows. One host synchronisation per stage.
  const torch::Tensor extent =
      torch::where(segment.valid, segment.end - segment.start, torch::zeros_like(segment.start));
  const double longest = extent.numel() > 0 ? extent.max().item<double>() : 0.0;
  const double diagonal = std::hypot(static_cast<double>(src_h), static_cast<double>(src_w));
  const int64_t length =
      std::max<int64_t>(1, static_cast<int64_t>(std::ceil(std::min(longest, diagonal))) + 1);

  const torch::Tensor steps =
      torch::arange(length, ref_features.options()).view({1, length, 1, 1});
  const torch::Tensor eflows = segment.start + steps;  // [B,L,h,w]
  inside_ = segment.valid & (eflows <= segment.end + 1e-3);

  // The fused lookup of correlation_cpu.h, centred on the middle of the L
  // samples, gives them all in one pass (sample k at base + (start + k) dir,
  // to float rounding); with autograd on, its backward is fused too.
  const torch::Tensor centre =
      segment.base_xy + (segment.start + 0.5 * static_cast<double>(length - 1)) * segment.dir;
  torch::Tensor volume;
  if (impl == CorrelationImpl::kAuto &&
      CanUseFusedCorrelation(src_features, ref_features, centre, segment.dir)) {
    volume = FusedCorrelationLookup({src_features.permute({0, 2, 3, 1}).contiguous()},
                                    ref_features, centre, segment.dir, length);
  } else {
    volume = AtenVolume(ref_features, src_features, segment, eflows);
  }
  volume = torch::where(inside_, volume, torch::zeros_like(volume));

  pyramid_.push_back(volume);
  for (int64_t l = 1; l < levels; ++l) {
    const torch::Tensor& previous = pyramid_.back();
    const int64_t len = previous.size(1);
    // Average pairs along k: [B,L,h*w] -> pool over L.
    const torch::Tensor pooled =
        F::avg_pool2d(previous.reshape({batch, 1, len, h * w}),
                      F::AvgPool2dFuncOptions({2, 1}).stride({2, 1}).ceil_mode(true));
    pyramid_.push_back(pooled.reshape({batch, pooled.size(2), h, w}));
  }
}

torch::Tensor SegmentCorrelation::SampleEflows() const {
  const int64_t length = this->length();
  return segment_.start +
         torch::arange(length, segment_.start.options()).view({1, length, 1, 1});
}

torch::Tensor SegmentCorrelation::Logits() const {
  const double scale = std::sqrt(static_cast<double>(feature_channels_));
  return torch::where(inside_, volume() * scale, torch::full_like(volume(), kOutsideLogit));
}

CorrelationSamples SegmentCorrelation::Lookup(const torch::Tensor& match_xy) const {
  const torch::Tensor& vol0 = volume();
  const std::vector<int64_t> grid2{vol0.size(0), 2, vol0.size(2), vol0.size(3)};
  Require(match_xy.defined() && match_xy.sizes() == torch::IntArrayRef(grid2),
          "Lookup: match_xy must be [B,2,h,w] on the reference grid");
  // Index along the segment of the match projected onto the line.
  const torch::Tensor e = (segment_.dir * (match_xy - segment_.base_xy)).sum(1, true);
  const torch::Tensor u = e - segment_.start;  // [B,1,h,w]
  const torch::Tensor offsets =
      (torch::arange(samples_, vol0.options()) - 0.5 * static_cast<double>(samples_ - 1))
          .view({1, samples_, 1, 1});
  std::vector<torch::Tensor> costs, insides;
  for (size_t l = 0; l < pyramid_.size(); ++l) {
    const double scale = static_cast<double>(int64_t{1} << l);
    const torch::Tensor ul = (u + 0.5) / scale - 0.5 + offsets;  // [B,S,h,w]
    const int64_t len = pyramid_[l].size(1);
    costs.push_back(Interpolate1d(pyramid_[l], ul));
    insides.push_back(segment_.valid & (ul >= 0) & (ul <= static_cast<double>(len - 1)));
  }
  return {torch::cat(costs, 1), torch::cat(insides, 1)};
}

SegmentMatch SegmentCorrelation::BestMatch() const {
  const torch::Tensor logits = Logits();  // [B,L,h,w]
  const int64_t length = this->length();
  const torch::Tensor probabilities = torch::softmax(logits, 1);
  const torch::Tensor peak = logits.argmax(1, /*keepdim=*/true);  // [B,1,h,w]
  // Soft-argmax over the window peak-2 .. peak+2 (clipped to the volume).
  constexpr int64_t kRadius = 2;
  const torch::Tensor offsets =
      torch::arange(-kRadius, kRadius + 1, peak.options()).view({1, 2 * kRadius + 1, 1, 1});
  const torch::Tensor index = peak + offsets;  // [B,5,h,w]
  const torch::Tensor exists = (index >= 0) & (index < length);
  const torch::Tensor safe = index.clamp(0, length - 1);
  const torch::Tensor p = torch::where(exists, probabilities.gather(1, safe),
                                       torch::zeros({}, probabilities.options()));
  const torch::Tensor mass = p.sum(1, true);
  const torch::Tensor safe_mass = torch::where(mass > 0, mass, torch::ones_like(mass));
  const torch::Tensor k = (p * index.to(p.scalar_type())).sum(1, true) / safe_mass;

  SegmentMatch match;
  match.valid = segment_.valid & inside_.any(1, true);
  match.eflow = torch::where(match.valid, segment_.start + k, torch::zeros_like(k));
  match.confidence = torch::where(match.valid, mass, torch::zeros_like(mass));
  return match;
}

}  // namespace dispmvs::model
