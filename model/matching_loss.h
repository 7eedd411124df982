#pragma once
// Direct matching supervision of model v2: a cross-entropy of the
// correlation along the epipolar segment against the ground-truth match.
//
// The sequence loss (loss.h) reaches the matching encoder only through the
// fused depth, behind detached GRU iterations: a weak, indirect signal. This
// loss trains the features to match: for every reference pixel of a stage and
// every source, the softmax of the matching logits over the samples along the
// line should put its mass on the ground-truth match (split linearly between
// the two samples around it, so the target is sub-pixel exact).
//
// Where the ground truth has no depth, the match leaves the sampled interval,
// or the reference point is occluded in the source (its depth there disagrees
// with the source's own ground-truth depth), the pair is masked out.

#include <cstdint>

#include <torch/torch.h>

#include "model/geometry.h"

namespace dispmvs::model {

// What a stage matched, per (reference, source) pair, in the batch layout of
// the driver ([B*N,...], index b*N + i). Sample k of a pixel is the source
// pixel base_xy + sample_eflow[k] * dir, at unit spacing in k.
struct StageMatching {
  int64_t stride = 0;          // stage resolution = full / stride (cells at stride * j)
  torch::Tensor logits;        // [B*N,S,h,w], kOutsideLogit where !inside
  torch::Tensor sample_eflow;  // [B*N,S,h,w]
  torch::Tensor inside;        // [B*N,S,h,w] bool
  torch::Tensor base_xy;       // [B*N,2,h,w] stage pixels
  torch::Tensor dir;           // [B*N,2,h,w] unit
};

// Ground-truth match of every stage pixel in every source: the source pixel
// (stage pixels) of the reference's ground-truth depth, and whether it counts.
struct GroundTruthMatches {
  torch::Tensor xy;     // [B*N,2,h,w]
  torch::Tensor valid;  // [B*N,1,h,w] bool
};

// depths [B,V,1,H,W] ground-truth depth of every view (0 = none; view 0 is
// the reference), intrinsics [B,V,3,3] at full resolution (pixel-index
// convention), extrinsics [B,V,4,4] world-to-camera. The stage's pixel
// (i, j) is the full-resolution pixel (stride*i, stride*j) (StridedIntrinsics),
// so its ground truth is read there without interpolation; the stage grid is
// stage_height x stage_width (the network pads the images, so it may extend
// past the image: cells there have no ground truth).
// A source whose depth map is all zero (not known) is not checked for
// occlusion. `occlusion_tolerance` is relative to the projected depth.
GroundTruthMatches ComputeGroundTruthMatches(const torch::Tensor& depths,
                                             const torch::Tensor& intrinsics,
                                             const torch::Tensor& extrinsics, int64_t stride,
                                             int64_t stage_height, int64_t stage_width,
                                             double occlusion_tolerance = 0.02);

struct MatchingLossResult {
  torch::Tensor loss;  // scalar: mean cross-entropy over counted pairs (0 if none)
  // For monitoring (no gradient): counted pairs, and how many have their
  // arg-max sample within one stage pixel of the ground truth (top-1).
  double count = 0;
  double top1 = 0;
  // How many have a sample within one stage pixel of the truth among the 2 /
  // 4 highest peaks of their logits (samples inside the image whose logit
  // is at least both neighbours'): how often the right match is among a
  // few candidates, what a design that keeps several matches through the
  // coarse iterations could reach. top1 <= top2_peaks <= top4_peaks.
  double top2_peaks = 0;
  double top4_peaks = 0;
};

// Cross-entropy of `matching` against `truth`. Throws std::invalid_argument
// on mismatched shapes.
MatchingLossResult MatchingLoss(const StageMatching& matching, const GroundTruthMatches& truth);

// Supervision of the matches themselves at every iteration of a stage, as
// RAFT supervises its flow: the distance in stage pixels between each
// (pixel, source) pair's matched source pixel and the true one, averaged
// over the pairs `truth` counts, summed over iterations with RAFT's weights
// (gamma^(n-1-i), the last 1). Where the fused depth loss reaches a source's
// match only through the fusion (which can weigh a bad source down), this
// asks every source to be right, to a fraction of a pixel. A pair's term is
// capped at kFlowLossCap stage pixels (no gradient beyond): a match that far
// off is the coarse stage's error, not a refinement the stage can make.
constexpr double kFlowLossCap = 8.0;
struct SourceFlowLossResult {
  torch::Tensor loss;       // scalar; 0 without a counted pair
  double count = 0;         // counted pairs
  double last_within_quarter = 0;  // of them, last iteration within 1/4 stage pixel (monitoring)
};
// matched_xy: one [B*N,2,h,w] per iteration, on truth's grid. Throws
// std::invalid_argument on an empty list, mismatched shapes or gamma outside
// (0, 1].
SourceFlowLossResult SourceFlowLoss(const std::vector<torch::Tensor>& matched_xy,
                                    const GroundTruthMatches& truth, double gamma = 0.9);

}  // namespace dispmvs::model
