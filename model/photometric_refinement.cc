#include "model/photometric_refinement.h"

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/dispmvs_net.h"
#include "model/geometry.h"
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
  if (steps < 1 || steps > 64) fail("steps must be in [1, 64]");
  if (!(step_pixels > 0 && step_pixels <= 8)) fail("step_pixels must be in (0, 8]");
  if (!(min_ncc >= -1 && min_ncc <= 1)) fail("min_ncc must be in [-1, 1]");
  if (!(min_texture >= 0 && std::isfinite(min_texture))) fail("min_texture must be >= 0");
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

  // Grey values; the reference's window statistics once, then a copy per
  // source for the per-hypothesis arithmetic ([B*N,1,H,W]).
  const torch::Tensor grey = images.to(opts).mean(2);  // [B,V,H,W]
  const torch::Tensor reference = grey.narrow(1, 0, 1);  // [B,1,H,W]
  const torch::Tensor reference_mean = WindowMean(reference, r);
  const torch::Tensor reference_var =
      torch::clamp_min(WindowMean(reference * reference, r) - reference_mean * reference_mean, 0);
  const torch::Tensor ref = reference.repeat_interleave(n, 0);
  const torch::Tensor ref_mean = reference_mean.repeat_interleave(n, 0);
  const torch::Tensor ref_var = reference_var.repeat_interleave(n, 0);
  const torch::Tensor src = grey.narrow(1, 1, n).reshape({b * n, 1, h, w});

  const torch::Tensor K = intrinsics.to(opts);
  const RelativePoses poses = ReferenceToSourcePoses(extrinsics.to(opts));
  const EpipolarPair pair =
      MakeEpipolarPair(K.select(1, 0).repeat_interleave(n, 0), K.narrow(1, 1, n).reshape({b * n, 3, 3}),
                       poses.R.reshape({b * n, 3, 3}), poses.T.reshape({b * n, 3}), h, w);

  const torch::Tensor depth_in = depth.to(opts);
  const torch::Tensor usable = valid.to(torch::kBool) & (depth_in > 0) & torch::isfinite(depth_in);
  const torch::Tensor w0 = torch::where(usable, 1.0 / depth_in, torch::zeros_like(depth_in));
  const torch::Tensor w0_per_source = w0.repeat_interleave(n, 0);

  // |dp_s/dw| = |b_xy a_z - a_xy b_z| / (a_z + w b_z)^2 (geometry.h): how far
  // the match moves per unit of inverse depth, in every source.
  const torch::Tensor a_z = pair.a.narrow(1, 2, 1), b_z = pair.b.narrow(1, 2, 1);
  const torch::Tensor along_x = pair.b.narrow(1, 0, 1) * a_z - pair.a.narrow(1, 0, 1) * b_z;
  const torch::Tensor along_y = pair.b.narrow(1, 1, 1) * a_z - pair.a.narrow(1, 1, 1) * b_z;
  const torch::Tensor denominator = a_z + w0_per_source * b_z;
  // (Written out: LibTorch's norm over the channel dimension took ten times longer.)
  torch::Tensor rate = torch::sqrt(along_x * along_x + along_y * along_y) / (denominator * denominator);
  rate = torch::where((denominator > 0) & torch::isfinite(rate), rate, torch::zeros_like(rate));
  const torch::Tensor max_rate = rate.view({b, n, h, w}).amax(1, /*keepdim=*/true);
  const torch::Tensor searchable = usable & (max_rate > 0);
  const torch::Tensor dw = torch::where(searchable, options.step_pixels / max_rate,
                                        torch::zeros_like(max_rate));

  // The projection of w0 + k dw is (P + k Q) / (P_z + k Q_z) with
  // P = a + w0 b and Q = dw b (geometry.h): two multiply-adds per hypothesis.
  const torch::Tensor dw_per_source = dw.repeat_interleave(n, 0);
  const torch::Tensor P = pair.a + w0_per_source * pair.b;  // [B*N,3,H,W]
  const torch::Tensor Q = dw_per_source * pair.b;
  const double x_scale = 2.0 / static_cast<double>(std::max<int64_t>(w - 1, 1));
  const double y_scale = 2.0 / static_cast<double>(std::max<int64_t>(h - 1, 1));
  // A source counts where the window around the match lies inside its
  // image: the match at least r pixels from the border (the window's other
  // pixels are sampled at their own matches, which lie about as far from it
  // as they lie from the reference pixel).
  const double margin = static_cast<double>(r);
  const double half_w = 0.5 * static_cast<double>(w - 1), half_h = 0.5 * static_cast<double>(h - 1);
  const auto grid_sample = F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kZeros).align_corners(true);
  // Every source's NCC at hypothesis k, and whether it counts ([B,N,H,W] each).
  const auto correlate = [&](int64_t k) {
    const torch::Tensor projected = torch::add(P, Q, static_cast<double>(k));
    const torch::Tensor z = projected.narrow(1, 2, 1);
    const torch::Tensor wk = torch::add(w0_per_source, dw_per_source, static_cast<double>(k));
    const torch::Tensor in_front = (z > 0) & (wk > 0);
    const torch::Tensor inverse_z = torch::where(in_front, z.reciprocal(), torch::zeros_like(z));
    const torch::Tensor x = projected.narrow(1, 0, 1) * inverse_z;
    const torch::Tensor y = projected.narrow(1, 1, 1) * inverse_z;
    const torch::Tensor inside = in_front & ((x - half_w).abs() <= half_w - margin) &
                                 ((y - half_h).abs() <= half_h - margin);
    const torch::Tensor grid = torch::stack({x.squeeze(1) * x_scale - 1.0, y.squeeze(1) * y_scale - 1.0}, -1);
    const torch::Tensor sampled = F::grid_sample(src, grid, grid_sample);
    // The three window means in one pass.
    const torch::Tensor means = WindowMean(torch::cat({sampled, sampled * sampled, ref * sampled}, 1), r);
    const torch::Tensor s_mean = means.narrow(1, 0, 1);
    const torch::Tensor s_var = torch::clamp_min(means.narrow(1, 1, 1) - s_mean * s_mean, 0);
    const torch::Tensor covariance = means.narrow(1, 2, 1) - ref_mean * s_mean;
    const torch::Tensor ncc = covariance * torch::rsqrt(torch::clamp_min(ref_var * s_var, 1e-12));
    const torch::Tensor ok = inside & (s_var > 1e-10);
    return std::make_pair(ncc.view({b, n, h, w}), ok.view({b, n, h, w}));
  };
  const auto [ncc_at_start, ok_at_start] = correlate(0);
  const torch::Tensor weights = BetterHalfOfSources(ncc_at_start, ok_at_start);
  const torch::Tensor weight_sum = weights.sum(1, /*keepdim=*/true);
  // A chosen source whose window leaves its image at some hypothesis scores
  // -1 there (the worst correlation): the search does not wander off the
  // sources it was judged on.
  const auto score = [&](const torch::Tensor& ncc, const torch::Tensor& ok) {
    const torch::Tensor per_source = torch::where(ok, ncc, torch::full_like(ncc, -1.0));
    return torch::where(weight_sum > 0, (per_source * weights).sum(1, true) / weight_sum.clamp_min(1),
                        torch::full_like(weight_sum, -1.0));
  };
  std::vector<torch::Tensor> scores;
  for (int64_t k = -options.steps; k <= options.steps; ++k) {
    if (k == 0) {
      scores.push_back(score(ncc_at_start, ok_at_start));
    } else {
      const auto [ncc, ok] = correlate(k);
      scores.push_back(score(ncc, ok));
    }
  }
  const torch::Tensor volume = torch::cat(scores, 1);  // [B,2K+1,H,W]
  const auto [best, best_index] = volume.max(1, /*keepdim=*/true);
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
  const torch::Tensor textured = torch::sqrt(reference_var) >= options.min_texture;
  const torch::Tensor refined = searchable & textured & (best_index > 0) & (best_index < last) &
                                (best >= options.min_ncc) & (before > -1) & (after > -1) & (w_new > 0);

  PhotometricRefinement result;
  result.valid = usable;
  result.refined = refined;
  result.depth = torch::where(refined, 1.0 / torch::where(refined, w_new, torch::ones_like(w_new)),
                              torch::where(usable, depth_in, torch::zeros_like(depth_in)));
  result.score = torch::where(searchable, best, torch::full_like(best, -1.0));
  return result;
}

PhotometricRefinement RefineDepthPhotometrically(const DispMvsInput& input,
                                                 const DispMvsOutput& output,
                                                 const PhotometricRefinementOptions& options) {
  return RefineDepthPhotometrically(input.images, input.intrinsics, input.extrinsics, output.depth,
                                    output.valid, options);
}

}  // namespace dispmvs::model
