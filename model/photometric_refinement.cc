#include "model/photometric_refinement.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include "model/depth_sweep.h"
#include "model/dispmvs_net.h"
#include "model/geometry.h"
#include "model/local_planes.h"
#include "model/nearest_plane.h"
#include "model/propagation_planes.h"
#include "model/shifted_windows.h"
#include "model/surface_ncc.h"
#include "model/window_mean.h"

namespace dispmvs::model {
namespace {

namespace F = torch::nn::functional;

// Per pixel, which sources count: the better half (at least one) of those
// whose window correlates validly at the network's depth, by that
// correlation. Chosen once, so that the hypotheses of a pixel are compared
// on the same sources; the worse half is where occlusion and other surfaces
// are. ncc, valid: [B,N,H,W]; returns the 0/1 weights [B,N,H,W].
torch::Tensor BetterHalfOfSources(const torch::Tensor& ncc, const torch::Tensor& valid) {
  const int64_t n = ncc.size(1);
  if (n == 1) return valid.to(ncc.scalar_type());
  const torch::Tensor ranked = torch::where(valid, ncc, torch::full_like(ncc, -3.0));
  const torch::Tensor count = valid.sum(1, /*keepdim=*/true);
  const torch::Tensor keep = torch::clamp_min(torch::div(count + 1, 2, "floor"), 1);
  // A source's rank: how many valid sources score higher (ties by index).
  const torch::Tensor index = torch::arange(n, ncc.options().dtype(torch::kLong)).view({1, n, 1, 1});
  torch::Tensor rank = torch::zeros_like(count).expand_as(ncc).clone();
  for (int64_t other = 0; other < n; ++other) {
    const torch::Tensor o = ranked.narrow(1, other, 1);
    rank += ((o > ranked) | ((o == ranked) & (index > other))).to(torch::kLong);
  }
  return (valid & (rank < keep)).to(ncc.scalar_type());
}

// Per batch item, the source the better half chose at most pixels
// (weights [B,N,H,W] 0/1): the sweep's one source. [B] long.
torch::Tensor SourceChosenMost(const torch::Tensor& weights) {
  return weights.sum({2, 3}).argmax(1);
}

// TakeBetterCandidates' update on one batch item's pixels [0, count). Loads
// first, comparisons as 0/1 integers and bool as bytes (GCC has no vector
// type for bool), unaliased pointers: the form GCC vectorises.
void TakeBetterInRange(const float* __restrict candidate, const float* __restrict candidate_score,
                       const uint8_t* __restrict allowed, float low, float high, float min_score, int64_t count,
                       float* __restrict w_out, float* __restrict current, uint8_t* __restrict changed) {
  for (int64_t p = 0; p < count; ++p) {
    const float c = candidate[p], score = candidate_score[p], now = current[p], w = w_out[p];
    const int take = static_cast<int>(allowed[p]) & static_cast<int>(c >= low) & static_cast<int>(c <= high) &
                     static_cast<int>(score >= min_score) & static_cast<int>(score > now);
    w_out[p] = take ? c : w;
    current[p] = take ? score : now;
    changed[p] = static_cast<uint8_t>(changed[p] | take);
  }
}

// Propagation's update, in place: where `allowed` and the candidate lies in
// [floor, ceiling] and scores at least min_ncc and better than `current`,
// it replaces w_out and current, and `changed` is set. One loop on CPU
// float maps (of one batch item's floor and ceiling each) instead of a
// dozen full-size operations; the same operations elsewhere.
void TakeBetterCandidates(const torch::Tensor& candidate, const torch::Tensor& candidate_score,
                          const torch::Tensor& allowed, const torch::Tensor& floor, const torch::Tensor& ceiling,
                          double min_ncc, torch::Tensor& w_out, torch::Tensor& current, torch::Tensor& changed) {
  const bool cpu = candidate.device().is_cpu() && candidate.scalar_type() == torch::kFloat32 &&
                   candidate_score.scalar_type() == torch::kFloat32 && w_out.scalar_type() == torch::kFloat32 &&
                   current.scalar_type() == torch::kFloat32 && w_out.is_contiguous() && current.is_contiguous() &&
                   changed.is_contiguous() && changed.scalar_type() == torch::kBool;
  if (!cpu) {
    const torch::Tensor take = allowed & (candidate >= floor) & (candidate <= ceiling) &
                               (candidate_score >= min_ncc) & (candidate_score > current);
    w_out = torch::where(take, candidate, w_out);
    current = torch::where(take, candidate_score, current);
    changed = changed | take;
    return;
  }
  const torch::Tensor c = candidate.contiguous(), s = candidate_score.contiguous(), a = allowed.contiguous();
  const torch::Tensor lo = floor.contiguous(), hi = ceiling.contiguous();
  const int64_t batch = c.size(0), plane = c.numel() / batch;
  const float* c_p = c.data_ptr<float>();
  const float* s_p = s.data_ptr<float>();
  const uint8_t* a_b = reinterpret_cast<const uint8_t*>(a.data_ptr<bool>());
  float* w_p = w_out.data_ptr<float>();
  float* cur_p = current.data_ptr<float>();
  uint8_t* ch_b = reinterpret_cast<uint8_t*>(changed.data_ptr<bool>());
  const float min_score = static_cast<float>(min_ncc);
  const float* low = lo.data_ptr<float>();
  const float* high = hi.data_ptr<float>();
  // Every pixel on its own: chunks in parallel (serial and branching, this
  // loop was a twentieth of the full-resolution refinement's time).
  at::parallel_for(0, batch * plane, 16384, [&](int64_t begin, int64_t end) {
    for (int64_t p = begin; p < end;) {
      const int64_t item = p / plane, stop = std::min(end, (item + 1) * plane);
      TakeBetterInRange(c_p + p, s_p + p, a_b + p, low[item], high[item], min_score, stop - p, w_p + p, cur_p + p,
                        ch_b + p);
      p = stop;
    }
  });
}

// The refinement's input at 1/scale of the resolution, for propagation at
// propagation_scale: images averaged over scale x scale blocks (rows and
// columns beyond the last whole block dropped), intrinsics for the
// pixel-index convention on that grid (full-resolution x lies at
// (x + 0.5) / scale - 0.5), and the inverse depth averaged over each
// block's usable pixels (valid where any is).
struct CoarseInput {
  torch::Tensor images, intrinsics, depth, valid;
};

CoarseInput Downsampled(const torch::Tensor& images, const torch::Tensor& intrinsics, const torch::Tensor& w,
                        const torch::Tensor& usable, int64_t scale) {
  const int64_t b = images.size(0), v = images.size(1), h = images.size(3), wd = images.size(4);
  const auto pool = [scale](const torch::Tensor& t) {
    return F::avg_pool2d(t, F::AvgPool2dFuncOptions(scale).stride(scale));
  };
  CoarseInput coarse;
  coarse.images = pool(images.reshape({b * v, 3, h, wd}));
  coarse.images = coarse.images.view({b, v, 3, coarse.images.size(2), coarse.images.size(3)});
  const double inverse = 1.0 / static_cast<double>(scale), shift = 0.5 * inverse - 0.5;
  const torch::Tensor to_coarse =
      torch::tensor({inverse, 0.0, shift, 0.0, inverse, shift, 0.0, 0.0, 1.0}, intrinsics.options()).view({3, 3});
  coarse.intrinsics = torch::matmul(to_coarse, intrinsics);
  const torch::Tensor m = usable.to(w.scalar_type());
  const torch::Tensor count = pool(m);
  coarse.valid = count > 0;
  coarse.depth = torch::where(coarse.valid, count / pool(w * m).clamp_min(1e-20), torch::zeros_like(count));
  return coarse;
}

// A coarse inverse-depth map (0: none) at full resolution [B,1,h,w]:
// bilinear between the coarse pixels that have one (weights renormalised
// over them), 0 where none is near or beyond the last whole block.
torch::Tensor UpsampledInverseDepth(const torch::Tensor& coarse_w, int64_t scale, int64_t h, int64_t w) {
  const auto up = [&](const torch::Tensor& t) {
    const torch::Tensor u = F::interpolate(t, F::InterpolateFuncOptions()
                                                  .scale_factor(std::vector<double>{static_cast<double>(scale),
                                                                                    static_cast<double>(scale)})
                                                  .mode(torch::kBilinear)
                                                  .align_corners(false)
                                                  .recompute_scale_factor(false));
    return F::pad(u, F::PadFuncOptions({0, w - u.size(3), 0, h - u.size(2)}));
  };
  const torch::Tensor m = (coarse_w > 0).to(coarse_w.scalar_type());
  const torch::Tensor weight = up(m);
  // Half the bilinear weight at least from coarse pixels with depth: no
  // extrapolation far over a hole's border.
  return torch::where(weight >= 0.5, up(coarse_w * m) / weight.clamp_min(1e-6), torch::zeros_like(weight));
}

void CheckShapes(const torch::Tensor& images, const torch::Tensor& intrinsics,
                 const torch::Tensor& extrinsics, const torch::Tensor& depth,
                 const torch::Tensor& valid) {
  const auto fail = [](const std::string& what) {
    throw std::invalid_argument("RefineDepthPhotometrically: " + what);
  };
  if (!images.defined() || images.dim() != 5 || images.size(1) < 2 || images.size(2) != 3) {
    fail("images must be [B,V,3,H,W] with V >= 2");
  }
  const int64_t b = images.size(0), v = images.size(1);
  const int64_t h = images.size(3), w = images.size(4);
  if (!intrinsics.defined() || intrinsics.sizes() != torch::IntArrayRef({b, v, 3, 3})) {
    fail("intrinsics must be [B,V,3,3]");
  }
  if (!extrinsics.defined() || extrinsics.sizes() != torch::IntArrayRef({b, v, 4, 4})) {
    fail("extrinsics must be [B,V,4,4]");
  }
  if (!depth.defined() || depth.sizes() != torch::IntArrayRef({b, 1, h, w})) {
    fail("depth must be [B,1,H,W] at the images' size");
  }
  if (!valid.defined() || valid.sizes() != depth.sizes()) fail("valid must be depth's shape");
}

}  // namespace

void PhotometricRefinementOptions::Check() const {
  const auto fail = [](const std::string& what) {
    throw std::invalid_argument("photometric refinement: " + what);
  };
  if (window_radius < 1 || window_radius > 15) fail("window_radius must be in [1, 15]");
  if (window_shift < 0 || window_shift > window_radius) fail("window_shift must be in [0, window_radius]");
  if (steps < 1 || steps > 64) fail("steps must be in [1, 64]");
  if (!(step_pixels > 0 && step_pixels <= 8)) fail("step_pixels must be in (0, 8]");
  if (!(min_ncc >= -1 && min_ncc <= 1)) fail("min_ncc must be in [-1, 1]");
  if (!(min_texture >= 0 && std::isfinite(min_texture))) fail("min_texture must be >= 0");
  if (propagation_rounds < 0 || propagation_rounds > 16) fail("propagation_rounds must be in [0, 16]");
  if (propagation_distance < 1 || propagation_distance > 256) {
    fail("propagation_distance must be in [1, 256]");
  }
  if (propagation_levels < 1 || propagation_levels > 16) fail("propagation_levels must be in [1, 16]");
  if (propagation_slope_radius < 1 || propagation_slope_radius > 64) {
    fail("propagation_slope_radius must be in [1, 64]");
  }
  if (propagation_scale != 1 && propagation_scale != 2 && propagation_scale != 4) {
    fail("propagation_scale must be 1, 2 or 4");
  }
  if (full_resolution_rounds < 0 || full_resolution_rounds > 16) fail("full_resolution_rounds must be in [0, 16]");
  if (full_resolution_levels < 1 || full_resolution_levels > 16) fail("full_resolution_levels must be in [1, 16]");
  if (sweep_hypotheses < 0 || sweep_hypotheses > 1024) fail("sweep_hypotheses must be in [0, 1024]");
  if (!(sweep_step_pixels > 0 && sweep_step_pixels <= 64)) fail("sweep_step_pixels must be in (0, 64]");
  if (unseen_slope_radius < 0 || unseen_slope_radius > 64) fail("unseen_slope_radius must be in [0, 64]");
  if (!(trusted_plane_min_ncc >= 0 && trusted_plane_min_ncc <= 1)) fail("trusted_plane_min_ncc must be in [0, 1]");
  if (trusted_plane_axis_anchors != 0 && trusted_plane_axis_anchors != 2 && trusted_plane_axis_anchors != 4) {
    fail("trusted_plane_axis_anchors must be 0, 2 or 4");
  }
  if (local_plane_radius < 0 || local_plane_radius > 16) fail("local_plane_radius must be in [0, 16]");
  if (!(local_plane_max_change > 0 && local_plane_max_change <= 1)) {
    fail("local_plane_max_change must be in (0, 1]");
  }
}

bool ParseRefinementMode(const std::string& value, const std::string& option) {
  if (value != "ncc" && value != "none") {
    throw std::invalid_argument(option + " must be ncc or none, got '" + value + "'");
  }
  return value == "ncc";
}

PhotometricRefinement RefineDepthPhotometrically(const torch::Tensor& images,
                                                 const torch::Tensor& intrinsics,
                                                 const torch::Tensor& extrinsics,
                                                 const torch::Tensor& depth,
                                                 const torch::Tensor& valid,
                                                 const PhotometricRefinementOptions& options) {
  options.Check();
  CheckShapes(images, intrinsics, extrinsics, depth, valid);
  torch::NoGradGuard no_grad;
  const torch::TensorOptions opts = images.options().dtype(torch::kFloat32);
  const int64_t b = images.size(0), v = images.size(1), n = v - 1;
  const int64_t h = images.size(3), w = images.size(4);
  const int64_t r = options.window_radius;

  // Grey values; the reference's window statistics once, shared by its
  // sources ([B,1,H,W]: surface_ncc.h reads them per batch item, not a copy
  // per source).
  const torch::Tensor images_float = images.to(opts);
  const torch::Tensor grey = images_float.mean(2);  // [B,V,H,W]
  const torch::Tensor reference = grey.narrow(1, 0, 1);  // [B,1,H,W]
  const torch::Tensor reference_mean = WindowMean(reference, r);
  const torch::Tensor reference_var =
      torch::clamp_min(WindowMean(reference * reference, r) - reference_mean * reference_mean, 0);
  const torch::Tensor src = grey.narrow(1, 1, n).reshape({b * n, 1, h, w});

  const torch::Tensor K = intrinsics.to(opts);
  const RelativePoses poses = ReferenceToSourcePoses(extrinsics.to(opts));
  const EpipolarPair pair =
      MakeEpipolarPair(K.select(1, 0).repeat_interleave(n, 0), K.narrow(1, 1, n).reshape({b * n, 3, 3}),
                       poses.R.reshape({b * n, 3, 3}), poses.T.reshape({b * n, 3}), h, w);

  const torch::Tensor depth_in = depth.to(opts);
  const torch::Tensor usable = valid.to(torch::kBool) & (depth_in > 0) & torch::isfinite(depth_in);
  const torch::Tensor w_network = torch::where(usable, 1.0 / depth_in, torch::zeros_like(depth_in));
  const bool coarse_propagation = options.propagation_rounds > 0 && options.propagation_scale > 1 &&
                                  h / options.propagation_scale >= 2 * r + 2 &&
                                  w / options.propagation_scale >= 2 * r + 2;

  // A source counts where the window around the match lies inside its
  // image: the match at least r pixels from the border (the window's other
  // pixels are sampled at their own matches, which lie about as far from it
  // as they lie from the reference pixel).
  const double margin = static_cast<double>(r);
  // Every source's NCC at the network's depth, and whether it counts.
  // Per source, [B*N,1,H,W]: kept only for the choice and the network
  // depth's score (at 24 megapixels and four sources each such map is 384 MB).
  torch::Tensor weights, network_score;
  {
    const SurfaceCorrelation at_network =
        CorrelateAlongSurface(src, reference, reference_mean, reference_var, pair.a, pair.b, w_network, r, margin);
    weights = BetterHalfOfSources(at_network.ncc.view({b, n, h, w}), at_network.ok.view({b, n, h, w}));
    network_score = CombineSources(at_network, weights);
  }
  // A chosen source whose window leaves its image at some hypothesis scores
  // -1 there (the worst correlation): the search does not wander off the
  // sources it was judged on (CombineSources, ScoreAlongSurface).
  const auto centred_score = [&](const torch::Tensor& surface) {
    return ScoreAlongSurface(src, reference, reference_mean, reference_var, pair.a, pair.b, surface, weights, r,
                             margin);
  };
  // What every hypothesis and candidate is compared by: the best of the
  // windows shifted by window_shift that contain the pixel
  // (shifted_windows.h). Where the centred window straddles a depth edge or
  // a patch the source sees differently, a shifted one can still confirm
  // the pixel's surface.
  const auto surface_score = [&](const torch::Tensor& surface) {
    return BestOfShiftedWindows(centred_score(surface), options.window_shift);
  };
  // What decides whether a pixel's depth is trusted (the long-range planes'
  // anchors, the local planes' support) is its own centred window: a pixel
  // beside a wrong block, a little off its surface, is confirmed by a window
  // shifted away from the block, and planes fitted through such pixels and
  // extended far are off (the unit test's block within 2 %: 0.988 against
  // 0.997). realval's MVS pairs within 2 % 0.626 against 0.624 with the
  // shifted scores there as well. Without shifts, the score at hand, as
  // before them (one correlation pass less).
  const auto own_window_score = [&](const torch::Tensor& surface, const torch::Tensor& score_at_hand) {
    return options.window_shift > 0 ? centred_score(surface) : score_at_hand;
  };
  const torch::Tensor textured = torch::sqrt(reference_var) >= options.min_texture;

  // Where the search starts: the network's depth, or, with propagation at a
  // coarser scale, that propagation's surface wherever it correlates better
  // at full resolution (on the same sources) than the network's.
  torch::Tensor w0 = w_network;
  // Scored as every candidate is, so that none wins by the shifts alone
  // (the network's depth unshifted against shifted candidates gave realval's
  // MVS pairs the same within 2 %: 0.624 both).
  torch::Tensor start_score = BestOfShiftedWindows(network_score, options.window_shift);
  // Where the start is no longer the network's depth (the sweep's or the
  // coarse propagation's surface took it): counts as refined.
  torch::Tensor start_replaced = torch::zeros_like(usable);
  // The sweep (depth_sweep.h) runs where the search starts from the
  // network's depth: in the coarse pass when there is one, else here.
  if (options.sweep_hypotheses > 0 && !coarse_propagation) {
    const torch::Tensor chosen = SourceChosenMost(weights);  // [B] per batch item
    const torch::Tensor pick = torch::arange(b, chosen.options()) * n + chosen;
    const torch::Tensor candidate =
        SweepInverseDepth(src.index_select(0, pick), reference, reference_mean, reference_var,
                          pair.a.index_select(0, pick), pair.b.index_select(0, pick), w_network, usable, r,
                          options.sweep_hypotheses, options.sweep_step_pixels);
    const torch::Tensor candidate_score = surface_score(candidate);
    const torch::Tensor take = (candidate > 0) & textured & (candidate_score >= options.min_ncc) &
                               (candidate_score > start_score);
    w0 = torch::where(take, candidate, w0);
    start_score = torch::where(take, candidate_score, start_score);
    start_replaced = take;
  }
  if (coarse_propagation) {
    const int64_t scale = options.propagation_scale;
    const CoarseInput coarse = Downsampled(images_float, K, w_network, usable, scale);
    PhotometricRefinementOptions coarse_options = options;
    coarse_options.propagation_scale = 1;
    // One coarse pixel per step (scale full-resolution pixels): the coarse
    // search is for reach, the full-resolution one for precision.
    coarse_options.step_pixels = 1.0;
    coarse_options.propagation_distance = std::max<int64_t>(1, options.propagation_distance / scale);
    coarse_options.propagation_slope_radius = std::max<int64_t>(1, options.propagation_slope_radius / scale);
    // Only the full-resolution map extends planes over unseen pixels: the
    // coarse pass's map is a candidate, taken where it correlates better.
    coarse_options.unseen_slope_radius = 0;
    // Long-range planes at full resolution only: in the coarse pass too
    // they gained 0.001 on realval's MVS pairs (docs/refinement-measurements.md).
    coarse_options.trusted_plane_min_ncc = 0.0;
    // Local planes run in the coarse pass too: its surface is the full
    // resolution's start (realval's MVS pairs within 2 % 0.612 against
    // 0.610 with them at full resolution alone).
    const PhotometricRefinement coarse_result = RefineDepthPhotometrically(
        coarse.images, coarse.intrinsics, extrinsics, coarse.depth, coarse.valid, coarse_options);
    // Inverse depth where the coarse pass changed it, 0 elsewhere (the
    // reciprocal's infinities at depth 0 are never selected).
    const torch::Tensor coarse_w = torch::where(coarse_result.refined, coarse_result.depth.reciprocal(),
                                                torch::zeros_like(coarse_result.depth));
    const torch::Tensor candidate =
        torch::where(usable, UpsampledInverseDepth(coarse_w, scale, h, w), torch::zeros_like(w_network));
    const torch::Tensor candidate_score = surface_score(candidate);
    start_replaced = (candidate > 0) & (candidate_score > start_score);
    w0 = torch::where(start_replaced, candidate, w_network);
    start_score = torch::where(start_replaced, candidate_score, start_score);
  }

  // How far the match moves per unit of inverse depth, in every source.
  const torch::Tensor max_rate =
      MatchShiftPerInverseDepth(pair, w0.repeat_interleave(n, 0)).view({b, n, h, w}).amax(1, /*keepdim=*/true);
  const torch::Tensor searchable = usable & (max_rate > 0);
  const torch::Tensor dw = torch::where(searchable, options.step_pixels / max_rate,
                                        torch::zeros_like(max_rate));

  // The search: its score volume and parabola go at the end of the block,
  // before propagation allocates its own maps.
  torch::Tensor best, refined, w_out;
  {
    torch::Tensor volume;  // [B,2K+1,H,W]
    {
      std::vector<torch::Tensor> scores;
      for (int64_t k = -options.steps; k <= options.steps; ++k) {
        if (k == 0) {
          scores.push_back(start_score);
        } else {
          scores.push_back(surface_score(torch::add(w0, dw, static_cast<double>(k))));
        }
      }
      volume = torch::cat(scores, 1);
    }
    torch::Tensor best_index;
    std::tie(best, best_index) = volume.max(1, /*keepdim=*/true);
    const int64_t last = 2 * options.steps;
    const torch::Tensor before = volume.gather(1, torch::clamp_min(best_index - 1, 0));
    const torch::Tensor after = volume.gather(1, torch::clamp_max(best_index + 1, last));
    // Parabola through the best score and its neighbours: its vertex.
    const torch::Tensor curvature = before - 2 * best + after;
    const torch::Tensor offset =
        torch::where(curvature < -1e-6, torch::clamp(0.5 * (before - after) / curvature, -0.5, 0.5),
                     torch::zeros_like(curvature));
    const torch::Tensor w_new =
        w0 + (best_index.to(opts.dtype()) - static_cast<double>(options.steps) + offset) * dw;
    refined = searchable & textured & (best_index > 0) & (best_index < last) & (best >= options.min_ncc) &
              (before > -1) & (after > -1) & (w_new > 0);
    w_out = torch::where(refined, w_new, w0);
  }
  torch::Tensor changed = refined | start_replaced;  // updated in place by propagation
  torch::Tensor best_out = best;
  torch::Tensor output_score = torch::where(refined, best, start_score);
  // Propagation at full resolution: all of it at scale 1; after a coarse
  // propagation, full_resolution_rounds more, with jumps as long in pixels
  // as the coarse ones were in coarse pixels.
  const int64_t fine_rounds = coarse_propagation ? options.full_resolution_rounds : options.propagation_rounds;
  const int64_t fine_levels = coarse_propagation ? options.full_resolution_levels : options.propagation_levels;
  const int64_t fine_distance =
      coarse_propagation ? std::max<int64_t>(1, options.propagation_distance / options.propagation_scale)
                         : options.propagation_distance;
  const bool trusted_planes = options.trusted_plane_min_ncc > 0;
  if (fine_rounds > 0 || trusted_planes) {
    // Propagation: every pixel tries the planes of pixels far away in four
    // directions, on the sources chosen above, and keeps the best-scoring
    // one; the jumps halve from fine_distance over fine_levels levels (the
    // full-resolution round's after a coarse propagation), so a right
    // surface crosses a wrong block of
    // the network's in a few steps (as PatchMatch's propagation does, but
    // on whole maps, so every candidate costs one warp and window pass).
    const torch::Tensor candidates_allowed = searchable & textured;
    // Candidates stay within the inverse depths the network gave this view:
    // a plane extrapolated over a long jump can reach inverse depths near 0,
    // depths without bound, where no surface was seen.
    const auto [w_floor, w_ceiling] = InverseDepthBounds(w0, usable);
    torch::Tensor current = surface_score(w_out);
    for (int64_t round = 0; round < fine_rounds; ++round) {
      int64_t distance = fine_distance;
      for (int64_t level = 0; level < fine_levels && distance >= 1; ++level, distance /= 2) {
        const auto [slope_x, slope_y] = LeastSquaresSlopes(w_out, usable, options.propagation_slope_radius);
        const int64_t offsets[4][2] = {{distance, 0}, {-distance, 0}, {0, distance}, {0, -distance}};
        for (const auto& offset : offsets) {
          const torch::Tensor candidate = PlaneFromNeighbour(w_out, slope_x, slope_y, offset[0], offset[1]);
          TakeBetterCandidates(candidate, surface_score(candidate), candidates_allowed, w_floor, w_ceiling,
                               options.min_ncc, w_out, current, changed);
        }
      }
    }
    if (trusted_planes) {
      // Long-range planes: every pixel tries the planes of the nearest
      // refined pixels whose windows correlate almost perfectly
      // (nearest_plane.h), however far, and keeps one where it correlates
      // better (as propagation's candidates). Propagation's jumps reach a
      // few dozen pixels, and its candidates come from whatever lies there,
      // wrong blocks included; these come from surfaces the images confirm,
      // across a whole wrong block: the nearest anchor of all, and with
      // trusted_plane_axis_anchors the nearest along the pixel's row and
      // column, on the block's other sides.
      const torch::Tensor anchor = changed & (own_window_score(w_out, current) >= options.trusted_plane_min_ncc);
      // Each anchor lends the plane fitted through the anchors around it,
      // its value there included, not its own depth: anchors along a wrong
      // block's border correlate well but sit a little off their surface,
      // and a plane extended far magnifies that (docs/refinement-measurements.md).
      const LeastSquaresPlane fit = LeastSquaresPlanes(w_out, anchor, kTrustedPlaneSlopeRadius);
      const torch::Tensor anchor_w = torch::where(fit.value > 0, fit.value, w_out);
      std::vector<torch::Tensor> nearest = {NearestAnchor(anchor)};
      if (options.trusted_plane_axis_anchors > 0) {
        const auto along_axes = NearestAnchorsAlongAxes(anchor);
        nearest.insert(nearest.end(), along_axes.begin(),
                       along_axes.begin() + options.trusted_plane_axis_anchors);
      }
      for (const torch::Tensor& from : nearest) {
        const torch::Tensor candidate = ExtendNearestPlaneWithin(anchor_w, fit.gx, fit.gy, from, w_floor, w_ceiling);
        // A plane may bring a pixel nearer, but take it at most
        // kTrustedPlaneMaxDepthRatio times further: the moves further than
        // that were what raised the generated scenes' mean relative error
        // (photometric_refinement.h).
        const torch::Tensor allowed = candidates_allowed & (candidate * kTrustedPlaneMaxDepthRatio >= w_out);
        TakeBetterCandidates(candidate, surface_score(candidate), allowed, w_floor, w_ceiling, options.min_ncc,
                             w_out, current, changed);
      }
    }
    best_out = torch::where(changed, current, best_out);
    output_score = current;
  }
  if (options.local_plane_radius > 0) {
    // Local planes (local_planes.h): each pixel takes the value of the plane
    // through its well-correlated neighbours where that lies near its own;
    // the search's and propagation's per-pixel NCC maxima each carry their
    // own error, which the plane averages out. Not scored again: the move is within
    // local_plane_max_change, and the score before it ranked the pixels as
    // well (realval's geometric maps within 2 % 0.490 against 0.488 scored
    // again, the photometric maps the same) for one correlation pass less.
    const torch::Tensor support = usable & (own_window_score(w_out, output_score) >= kLocalPlaneMinNcc);
    const LocalPlaneSnap snap =
        SnapToLocalPlanes(w_out, support, usable, options.local_plane_radius, options.local_plane_max_change);
    w_out = snap.w;
    changed = changed | snap.snapped;
  }
  if (options.unseen_slope_radius > 0) {
    // Pixels no source sees at their depth (nearest_plane.h): the plane of
    // the nearest refined pixel that a source sees well inside its image
    // (the last few pixels before a source's border were not refined: their
    // windows leave the image), kept within the inverse depths the network
    // gave the view (as propagation's candidates are).
    const torch::Tensor inside = DistanceInsideSources(pair, w_out, n, h, w);
    const torch::Tensor unseen = usable & ~(inside >= 0);
    // Most views of a capture with several sources have none: then nothing
    // more to compute.
    if (unseen.any().item<bool>()) {
      const torch::Tensor anchor = changed & (inside >= kUnseenAnchorMargin);
      const auto [low, high] = InverseDepthBounds(w_network, usable);
      const torch::Tensor w_extended =
          ExtendTrustedPlanes(w_out, anchor, options.unseen_slope_radius, low, high, kUnseenMaxChange);
      const torch::Tensor take = unseen & (w_extended > 0);
      w_out = torch::where(take, w_extended, w_out);
      changed = changed | take;
      // No source scores the extended depth.
      output_score = torch::where(take, torch::full_like(output_score, -1.0), output_score);
    }
  }

  PhotometricRefinement result;
  result.valid = usable;
  result.refined = changed;
  result.depth = torch::where(changed, 1.0 / torch::where(changed, w_out, torch::ones_like(w_out)),
                              torch::where(usable, depth_in, torch::zeros_like(depth_in)));
  result.score = torch::where(searchable, best_out, torch::full_like(best_out, -1.0));
  result.output_score = torch::where(searchable, output_score, torch::full_like(output_score, -1.0));
  result.texture = torch::sqrt(reference_var);
  result.signal_support = WindowMean((result.texture >= kSignalFloor).to(opts), kSignalRadius);
  return result;
}

PhotometricRefinement RefineDepthPhotometrically(const DispMvsInput& input,
                                                 const DispMvsOutput& output,
                                                 const PhotometricRefinementOptions& options) {
  return RefineDepthPhotometrically(input.images, input.intrinsics, input.extrinsics, output.depth,
                                    output.valid, options);
}

}  // namespace dispmvs::model
