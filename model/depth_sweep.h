#pragma once
// A fronto-parallel sweep that gives the photometric refinement
// (photometric_refinement.h) a second start, far from the network's depth
// where the network chose the wrong surface.
//
// Why: the refinement's search moves each pixel a few pixels along its
// epipolar line, and propagation only spreads surfaces that some pixel
// already has. Where the network put a whole region on a wrong surface
// (wide baselines, repeated texture), the truth often correlates better than
// the network's depth (on realval's 21 MVS pairs, about half of the pixels
// more than 2 % off: docs/refinement-measurements.md, "The sweep"), but no candidate reaches
// it. A sweep over the network's own inverse-depth range tries every depth
// at every pixel once.
//
// For one source per view (the caller's choice: the one the refinement
// chose at most pixels), and constant inverse depths w_k spaced so that
// consecutive ones move the match by about `step_pixels` pixels at the
// median pixel (at most `max_hypotheses` of them, evenly over
// [min, max] of the start's inverse depth): each hypothesis is scored by
// the refinement's NCC along the constant surface, the score averaged over
// (2 kAggregationRadius + 1)^2 pixels (a single window is too small to tell
// repeated texture apart), the best w_k kept per pixel (winner takes all),
// and the winners' map median-filtered over (2 kMedianRadius + 1)^2 pixels
// (single wrong winners removed, region borders kept). The result is only a
// candidate: the refinement takes it where it correlates better than its
// start, on all its chosen sources. The median is taken of the winners'
// hypothesis indices, over the usable pixels of each window.
//
// Tensors as in surface_ncc.h with one source per batch item (N = 1):
// source, reference, reference_mean, reference_var [B,1,H,W]; a [B,3,H,W];
// b [B,3,H,W] or [B,3,1,1]; start [B,1,H,W] inverse depth (<= 0: none);
// usable [B,1,H,W] bool. Returns the candidate inverse depth [B,1,H,W], 0
// where not usable or where the sweep has fewer than 2 hypotheses (a batch
// item without usable pixels, or no parallax). Throws std::invalid_argument
// on bad shapes or settings (max_hypotheses < 0, step_pixels <= 0).

#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::model {

// The sweep's smoothing, in pixels of the grid it runs on (the coarse grid
// of propagation_scale 2 by default). On realval's mvs_013, the pair that
// gains most, within 2 %: neither 13.1 % (no sweep); median radius 2
// 19.7 %, 4 22.0 %, 8 22.8 %; aggregation radius 4 alone 21.1 %; both 4
// 23.2 %.
constexpr int64_t kSweepAggregationRadius = 4;
constexpr int64_t kSweepMedianRadius = 4;

torch::Tensor SweepInverseDepth(const torch::Tensor& source, const torch::Tensor& reference,
                                const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                                const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& start,
                                const torch::Tensor& usable, int64_t radius, int64_t max_hypotheses,
                                double step_pixels);

// The median of every (2r+1) x (2r+1) window (clipped at the border) of a
// map of levels 0 .. count-1 ([B,1,H,W] long), over the window's pixels
// where `mask` ([B,1,H,W] bool): the smallest level that at least half of
// them are at or below (the lower median of an even number). -1 where a
// window has no such pixel. A window median of a float map would sort
// (2r+1)^2 values per pixel, 70-190 ms at 320 x 240 and r = 4; this is
// `count` window sums. Throws std::invalid_argument on bad shapes or types.
torch::Tensor WindowMedianLevel(const torch::Tensor& levels, const torch::Tensor& mask, int64_t count,
                                int64_t radius);

}  // namespace dispmvs::model
