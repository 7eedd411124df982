#pragma once
// The coarse correlation of model v2: a 1-D volume along the whole epipolar
// segment, computed once per stage (as RAFT-Stereo and CER-MVS compute their
// volumes once and look them up at every iteration).
//
// For every reference pixel and source view, sample k (k = 0 .. L-1) sits at
// E-flow e_k = segment.start + k along the segment (one stage pixel apart,
// starting at the far end), at source pixel base + e_k * dir; its value is the
// similarity <f_ref, f_src(e_k)> / C (bilinear source features, as
// EpipolarCorrelation). L is the longest segment of the batch (rounded up,
// plus one); samples past a pixel's own segment end are outside (value 0).
//
// Lookup(match) reads the same layout as EpipolarCorrelation::Lookup, so
// the update block is unchanged: `levels` levels of the volume average-pooled
// along k by 2 (ceil), `samples` samples per level at one level-pixel spacing
// around the current match, linear interpolation along k, 0 outside. A match
// at E-flow e has level-0 index u = e - start and level-l index
// (u + 0.5) / 2^l - 0.5 (the centre of a pooled pair of samples).
//
// BestMatch() is the range-free start: the arg-max along each segment,
// refined to sub-pixel by a soft-argmax in a +-2 window around it.

#include <cstdint>
#include <vector>

#include <torch/torch.h>

#include "model/correlation.h"
#include "model/geometry.h"

namespace dispmvs::model {

struct SegmentMatch {
  torch::Tensor eflow;       // [B,1,h,w] E-flow of the best match (segment frame)
  torch::Tensor confidence;  // [B,1,h,w] softmax mass along the segment within +-2 of the peak
  torch::Tensor valid;       // [B,1,h,w] bool: the segment has at least one sample
};

class SegmentCorrelation {
 public:
  // Logits of the matching distribution are similarity * sqrt(C): with the
  // volume's dot / C normalisation, unit-variance features give logits of
  // unit scale.
  // ref_features [B,C,h,w]; src_features [B,C,H,W]; segment on the (h,w)
  // grid for a (H,W) source. levels, samples >= 1. L never exceeds the
  // source diagonal + 2 (a clipped segment cannot be longer). `impl` as
  // EpipolarCorrelation's (kAtenOps: the reference for tests).
  // Throws std::invalid_argument on bad shapes or counts.
  SegmentCorrelation(const torch::Tensor& ref_features, const torch::Tensor& src_features,
                     const EpipolarSegment& segment, int64_t levels, int64_t samples,
                     CorrelationImpl impl = CorrelationImpl::kAuto);

  // The pyramid lookup at the current match (source pixel [B,2,h,w], stage
  // pixels; it is projected onto the segment's line).
  CorrelationSamples Lookup(const torch::Tensor& match_xy) const;

  SegmentMatch BestMatch() const;

  // Level-0 volume [B,L,h,w] (0 outside), the E-flow of every sample
  // [B,L,h,w], and whether the sample lies on the segment [B,L,h,w].
  const torch::Tensor& volume() const { return pyramid_.front(); }
  torch::Tensor SampleEflows() const;
  const torch::Tensor& inside() const { return inside_; }
  // Matching logits [B,L,h,w]: volume * sqrt(C), very negative outside.
  torch::Tensor Logits() const;
  const EpipolarSegment& segment() const { return segment_; }
  int64_t length() const { return volume().size(1); }
  int64_t channels() const { return feature_channels_; }

 private:
  EpipolarSegment segment_;
  std::vector<torch::Tensor> pyramid_;  // [B,L_l,h,w]
  torch::Tensor inside_;
  int64_t samples_;
  int64_t feature_channels_;
};

// Logit given to samples outside a segment: exp() of it is 0 in float32 and
// it stays finite (no NaN in a masked softmax's backward).
constexpr double kOutsideLogit = -1e4;

}  // namespace dispmvs::model
