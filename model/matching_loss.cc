#include "model/matching_loss.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/dispmvs_net.h"  // ReferenceToSourcePoses
#include "model/grid_coordinates.h"
#include "model/segment_correlation.h"

namespace dispmvs::model {
namespace {

namespace F = torch::nn::functional;

void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

// Bilinear read of a depth map [B,1,H,W] at pixel-index positions xy
// [B,2,h,w]; only where all four neighbours have depth (no mixing of a
// surface with the background), else 0.
torch::Tensor ReadDepth(const torch::Tensor& depth, const torch::Tensor& xy) {
  const int64_t height = depth.size(2), width = depth.size(3);
  const torch::Tensor grid = torch::stack({ToGridCoordinate(xy.select(1, 0), width),
                                           ToGridCoordinate(xy.select(1, 1), height)},
                                          -1);  // [B,h,w,2]
  const auto options = F::GridSampleFuncOptions()
                           .mode(torch::kBilinear)
                           .padding_mode(torch::kZeros)
                           .align_corners(false);
  const torch::Tensor has_depth = (depth > 0).to(depth.scalar_type());
  const torch::Tensor value = F::grid_sample(depth, grid, options);
  // Fraction of the footprint with depth: 1 only if all four neighbours have it.
  const torch::Tensor coverage = F::grid_sample(has_depth, grid, options);
  return torch::where(coverage > 1.0 - 1e-4, value, torch::zeros_like(value));
}

}  // namespace

GroundTruthMatches ComputeGroundTruthMatches(const torch::Tensor& depths,
                                             const torch::Tensor& intrinsics,
                                             const torch::Tensor& extrinsics, int64_t stride,
                                             int64_t stage_height, int64_t stage_width,
                                             double occlusion_tolerance) {
  Require(depths.defined() && depths.dim() == 5 && depths.size(2) == 1 && depths.size(1) >= 2,
          "ComputeGroundTruthMatches: depths must be [B,V,1,H,W], V >= 2");
  const int64_t b = depths.size(0), v = depths.size(1), n = v - 1;
  const int64_t height = depths.size(3), width = depths.size(4);
  Require(intrinsics.defined() && intrinsics.sizes() == torch::IntArrayRef({b, v, 3, 3}),
          "ComputeGroundTruthMatches: intrinsics must be [B,V,3,3]");
  Require(extrinsics.defined() && extrinsics.sizes() == torch::IntArrayRef({b, v, 4, 4}),
          "ComputeGroundTruthMatches: extrinsics must be [B,V,4,4]");
  Require(stride >= 1, "ComputeGroundTruthMatches: stride must be >= 1");
  Require(stage_height >= 1 && stage_width >= 1, "ComputeGroundTruthMatches: empty stage grid");
  const torch::TensorOptions opts = depths.options();

  // Reference depth at the stage cells (stride*i, stride*j); none past the image.
  const torch::Tensor strided = depths.select(1, 0).slice(2, 0, height, stride).slice(3, 0, width, stride);
  const int64_t h = stage_height, w = stage_width;
  torch::Tensor ref_depth = torch::zeros({b, 1, h, w}, opts);
  const int64_t copy_h = std::min(h, strided.size(2)), copy_w = std::min(w, strided.size(3));
  ref_depth.narrow(2, 0, copy_h).narrow(3, 0, copy_w).copy_(strided.narrow(2, 0, copy_h).narrow(3, 0, copy_w));

  // Full-resolution geometry of the subsampled reference pixels: the stage
  // cell (i, j) with StridedIntrinsics(K_ref, stride) is exactly the
  // full-resolution pixel (stride*i, stride*j).
  const torch::Tensor K = intrinsics.to(opts);
  const RelativePoses poses = ReferenceToSourcePoses(extrinsics.to(opts));
  const torch::Tensor K_ref_stage =
      StridedIntrinsics(K.select(1, 0), static_cast<double>(stride)).unsqueeze(1).expand({b, n, 3, 3});
  const EpipolarPair full = MakeEpipolarPair(
      K_ref_stage.reshape({b * n, 3, 3}), K.narrow(1, 1, n).reshape({b * n, 3, 3}),
      poses.R.reshape({b * n, 3, 3}), poses.T.reshape({b * n, 3}), h, w);

  const torch::Tensor ref_rep =
      ref_depth.unsqueeze(1).expand({b, n, 1, h, w}).reshape({b * n, 1, h, w});
  const torch::Tensor has_gt = (ref_rep > 0) & torch::isfinite(ref_rep);
  const torch::Tensor inv = torch::where(has_gt, 1.0 / torch::where(has_gt, ref_rep, torch::ones_like(ref_rep)),
                                         torch::zeros_like(ref_rep));
  const SourcePixels projected = ProjectInverseDepth(full, inv);  // full-resolution source pixels
  torch::Tensor valid = has_gt & projected.valid;

  // Occlusion: the source's own depth at the projection must agree with the
  // depth of the reference point in the source camera, z_s = (a_z + w b_z) / w.
  const torch::Tensor src_depths = depths.narrow(1, 1, n).reshape({b * n, 1, height, width});
  const torch::Tensor z_src = (full.a.narrow(1, 2, 1) + inv * full.b.narrow(1, 2, 1)) /
                              torch::where(has_gt, inv, torch::ones_like(inv));
  const torch::Tensor seen = ReadDepth(src_depths, projected.xy);
  const torch::Tensor known = (src_depths > 0).flatten(1).any(1).view({b * n, 1, 1, 1});
  const torch::Tensor agrees = (seen - z_src).abs() <= occlusion_tolerance * z_src.abs();
  valid = valid & torch::where(known, agrees & (seen > 0), torch::ones_like(agrees));

  GroundTruthMatches out;
  out.xy = torch::where(valid, projected.xy / static_cast<double>(stride), torch::zeros_like(projected.xy));
  out.valid = valid;
  return out;
}

MatchingLossResult MatchingLoss(const StageMatching& m, const GroundTruthMatches& truth) {
  Require(m.logits.defined() && m.logits.dim() == 4, "MatchingLoss: logits must be [B',S,h,w]");
  const auto sizes = m.logits.sizes();
  const std::vector<int64_t> grid2{sizes[0], 2, sizes[2], sizes[3]};
  const std::vector<int64_t> grid1{sizes[0], 1, sizes[2], sizes[3]};
  Require(m.sample_eflow.sizes() == sizes && m.inside.sizes() == sizes,
          "MatchingLoss: sample_eflow and inside must have the logits' shape");
  Require(m.base_xy.sizes() == torch::IntArrayRef(grid2) && m.dir.sizes() == torch::IntArrayRef(grid2),
          "MatchingLoss: base_xy and dir must be [B',2,h,w]");
  Require(truth.xy.defined() && truth.xy.sizes() == torch::IntArrayRef(grid2) &&
              truth.valid.sizes() == torch::IntArrayRef(grid1),
          "MatchingLoss: ground truth must be on the stage grid, got " +
              (truth.xy.defined() ? c10::str(truth.xy.sizes()) : std::string("undefined")) +
              " for logits " + c10::str(sizes));
  const int64_t samples = sizes[1];

  // Position of the truth in sample units: samples are one stage pixel apart.
  const torch::Tensor e_gt = (m.dir * (truth.xy - m.base_xy)).sum(1, true);
  const torch::Tensor k_gt = e_gt - m.sample_eflow.narrow(1, 0, 1);  // [B',1,h,w]
  const torch::Tensor lower = k_gt.floor();
  const torch::Tensor frac = k_gt - lower;
  const torch::Tensor i0 = lower.clamp(0, samples - 1).to(torch::kLong);
  const torch::Tensor i1 = (lower + 1).clamp(0, samples - 1).to(torch::kLong);
  const torch::Tensor line_ok = (m.dir.abs().sum(1, true) > 0.5);
  torch::Tensor counted = truth.valid & line_ok & (lower >= 0) & (lower + 1 <= samples - 1) &
                          m.inside.gather(1, i0) & m.inside.gather(1, i1);

  const torch::Tensor log_p = torch::log_softmax(m.logits, 1);
  const torch::Tensor nll = -((1.0 - frac) * log_p.gather(1, i0) + frac * log_p.gather(1, i1));
  const torch::Tensor counted_f = counted.to(nll.scalar_type());
  const torch::Tensor count = counted_f.sum();
  MatchingLossResult result;
  result.loss = (torch::where(counted, nll, torch::zeros_like(nll))).sum() / count.clamp_min(1.0);

  torch::NoGradGuard no_grad;
  const torch::Tensor best = m.logits.argmax(1, true);
  const torch::Tensor e_best = m.sample_eflow.gather(1, best);
  const torch::Tensor hit = counted & ((e_best - e_gt).abs() <= 1.0);
  result.count = count.item<double>();
  result.top1 = hit.sum().item<double>();

  // The peaks: local maxima along the segment (the arg-max is one), inside.
  const torch::Tensor lowest = torch::full_like(m.logits.narrow(1, 0, 1), -std::numeric_limits<double>::infinity());
  const torch::Tensor before = torch::cat({lowest, m.logits.narrow(1, 0, samples - 1)}, 1);
  const torch::Tensor after = torch::cat({m.logits.narrow(1, 1, samples - 1), lowest}, 1);
  const torch::Tensor is_peak = m.inside & (m.logits >= before) & (m.logits >= after);
  const torch::Tensor peak_logits = torch::where(is_peak, m.logits, lowest.expand_as(m.logits));
  const auto [best_peaks, peak_index] = peak_logits.topk(std::min<int64_t>(4, samples), 1);
  const torch::Tensor near_truth =
      torch::isfinite(best_peaks) & ((m.sample_eflow.gather(1, peak_index) - e_gt).abs() <= 1.0);
  // The arg-max counts even where it is outside or flat (top1 above), so
  // that the k-peak shares never fall below top-1.
  const auto hits_among = [&](int64_t k) {
    const torch::Tensor any = near_truth.narrow(1, 0, std::min(k, near_truth.size(1))).any(1, true);
    return (counted & (any | hit)).sum().item<double>();
  };
  result.top2_peaks = hits_among(2);
  result.top4_peaks = hits_among(4);
  return result;
}

SourceFlowLossResult SourceFlowLoss(const std::vector<torch::Tensor>& matched_xy,
                                    const GroundTruthMatches& truth, double gamma) {
  Require(!matched_xy.empty(), "SourceFlowLoss: no iteration");
  Require(gamma > 0.0 && gamma <= 1.0, "SourceFlowLoss: gamma must be in (0, 1]");
  Require(truth.xy.defined() && truth.xy.dim() == 4 && truth.xy.size(1) == 2 && truth.valid.defined(),
          "SourceFlowLoss: ground truth must be [B',2,h,w] with its mask");
  for (const torch::Tensor& xy : matched_xy) {
    Require(xy.defined() && xy.sizes() == truth.xy.sizes(),
            "SourceFlowLoss: every iteration's matches must be on the ground truth's grid, got " +
                (xy.defined() ? c10::str(xy.sizes()) : std::string("undefined")) + " for " +
                c10::str(truth.xy.sizes()));
  }
  // Non-finite matches (no valid line) are left out, as invalid truth is.
  const torch::Tensor truth_xy = torch::where(truth.valid, truth.xy, torch::zeros_like(truth.xy));
  torch::Tensor counted = truth.valid;
  for (const torch::Tensor& xy : matched_xy) counted = counted & torch::isfinite(xy).all(1, true);
  const torch::Tensor counted_f = counted.to(truth_xy.scalar_type());
  const torch::Tensor count = counted_f.sum();
  const int64_t n = static_cast<int64_t>(matched_xy.size());
  SourceFlowLossResult result;
  result.loss = torch::zeros({}, truth_xy.options());
  torch::Tensor last_error;
  for (int64_t i = 0; i < n; ++i) {
    const torch::Tensor xy = torch::where(counted, matched_xy[static_cast<size_t>(i)], truth_xy);
    // sqrt(d^2 + eps): a distance with a finite gradient at 0.
    const torch::Tensor error = ((xy - truth_xy).pow(2).sum(1, true) + 1e-8).sqrt();
    const torch::Tensor term = (error.clamp_max(kFlowLossCap) * counted_f).sum() / count.clamp_min(1.0);
    result.loss = result.loss + std::pow(gamma, static_cast<double>(n - 1 - i)) * term;
    if (i + 1 == n) last_error = error.detach();
  }
  result.count = count.item<double>();
  result.last_within_quarter = (counted & (last_error <= 0.25)).sum().item<double>();
  return result;
}

}  // namespace dispmvs::model
