#include "train/source_pixel_metrics.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <vector>

#include "model/dispmvs_net.h"
#include "model/geometry.h"
#include "model/matching_loss.h"

namespace dispmvs::train {

SourcePixelCounts& SourcePixelCounts::operator+=(const SourcePixelCounts& other) {
  seeing_pairs += other.seeing_pairs;
  pairs_within_1px += other.pairs_within_1px;
  pairs_within_2px += other.pairs_within_2px;
  seen_pixels += other.seen_pixels;
  moves_1px += other.moves_1px;
  moves_half_px += other.moves_half_px;
  return *this;
}

namespace {

// 1 / depth where `ok`, else 0 (ProjectInverseDepth's vanishing point, never
// counted: callers mask those pixels).
torch::Tensor InverseWhere(const torch::Tensor& depth, const torch::Tensor& ok) {
  return torch::where(ok, 1.0 / torch::where(ok, depth, torch::ones_like(depth)),
                      torch::zeros_like(depth));
}

int64_t Count(const torch::Tensor& mask) { return mask.sum().item<int64_t>(); }

}  // namespace

SourcePixelCounts CountSourcePixels(const torch::Tensor& gt_depths, const torch::Tensor& intrinsics,
                                    const torch::Tensor& extrinsics, const torch::Tensor& pred_depth,
                                    const torch::Tensor& pred_valid, torch::Tensor* seen) {
  if (!gt_depths.defined() || gt_depths.dim() != 5 || gt_depths.size(1) < 2 ||
      gt_depths.size(2) != 1) {
    throw std::invalid_argument("CountSourcePixels: gt_depths must be [B,V,1,H,W], V >= 2");
  }
  const int64_t b = gt_depths.size(0), n = gt_depths.size(1) - 1;
  const int64_t height = gt_depths.size(3), width = gt_depths.size(4);
  const std::vector<int64_t> map_shape{b, 1, height, width};
  if (!pred_depth.defined() || pred_depth.sizes() != torch::IntArrayRef(map_shape) ||
      !pred_valid.defined() || pred_valid.sizes() != torch::IntArrayRef(map_shape)) {
    throw std::invalid_argument(
        "CountSourcePixels: pred_depth and pred_valid must be " + c10::str(map_shape) + ", got " +
        (pred_depth.defined() ? c10::str(pred_depth.sizes()) : std::string("undefined")) + " and " +
        (pred_valid.defined() ? c10::str(pred_valid.sizes()) : std::string("undefined")));
  }
  // Checks the cameras' shapes too.
  const model::GroundTruthMatches truth = model::ComputeGroundTruthMatches(
      gt_depths, intrinsics, extrinsics, /*stride=*/1, height, width);
  const torch::Tensor pair_seen = truth.valid;  // [B*N,1,H,W], pair b*N + i

  const torch::TensorOptions f64 = gt_depths.options().dtype(torch::kFloat64);
  const torch::Tensor K = intrinsics.to(f64);
  const model::RelativePoses poses = model::ReferenceToSourcePoses(extrinsics.to(f64));
  const model::EpipolarPair pair = model::MakeEpipolarPair(
      K.select(1, 0).unsqueeze(1).expand({b, n, 3, 3}).reshape({b * n, 3, 3}),
      K.narrow(1, 1, n).reshape({b * n, 3, 3}), poses.R.reshape({b * n, 3, 3}),
      poses.T.reshape({b * n, 3}), height, width);
  const auto per_pair = [&](const torch::Tensor& map) {  // [B,1,H,W] -> [B*N,1,H,W]
    return map.unsqueeze(1).expand({b, n, 1, height, width}).reshape({b * n, 1, height, width});
  };

  const torch::Tensor gt = per_pair(gt_depths.select(1, 0).to(f64));
  const torch::Tensor gt_ok = (gt > 0) & torch::isfinite(gt);
  const torch::Tensor at_truth = model::ProjectInverseDepth(pair, InverseWhere(gt, gt_ok)).xy;
  const auto distance = [&](const torch::Tensor& xy) { return (xy - at_truth).norm(2, 1, true); };
  const torch::Tensor move = torch::minimum(
      distance(model::ProjectInverseDepth(pair, InverseWhere(gt * 1.02, gt_ok)).xy),
      distance(model::ProjectInverseDepth(pair, InverseWhere(gt * 0.98, gt_ok)).xy));

  const torch::Tensor pred = per_pair(pred_depth.to(f64));
  const torch::Tensor pred_ok =
      per_pair(pred_valid.to(torch::kBool)) & torch::isfinite(pred) & (pred > 0);
  const model::SourcePixels predicted = model::ProjectInverseDepth(pair, InverseWhere(pred, pred_ok));
  const torch::Tensor error =
      torch::where(pred_ok & predicted.valid, distance(predicted.xy),
                   torch::full_like(move, std::numeric_limits<double>::infinity()));

  const torch::Tensor seen_pixels = pair_seen.view({b, n, 1, height, width}).any(1);
  const torch::Tensor best_move =
      torch::where(pair_seen, move, torch::zeros_like(move)).view({b, n, 1, height, width}).amax(1);
  SourcePixelCounts counts;
  counts.seeing_pairs = Count(pair_seen);
  counts.pairs_within_1px = Count(pair_seen & (error < 1.0));
  counts.pairs_within_2px = Count(pair_seen & (error < 2.0));
  counts.seen_pixels = Count(seen_pixels);
  counts.moves_1px = Count(seen_pixels & (best_move >= 1.0));
  counts.moves_half_px = Count(seen_pixels & (best_move >= 0.5));
  if (seen != nullptr) *seen = seen_pixels;
  return counts;
}

SourcePixelShares SharesOf(const SourcePixelCounts& c) {
  const auto share = [](int64_t part, int64_t whole) {
    return whole > 0 ? static_cast<double>(part) / static_cast<double>(whole) : 0.0;
  };
  SourcePixelShares s;
  s.within_1px = share(c.pairs_within_1px, c.seeing_pairs);
  s.within_2px = share(c.pairs_within_2px, c.seeing_pairs);
  s.moves_1px = share(c.moves_1px, c.seen_pixels);
  s.moves_half_px = share(c.moves_half_px, c.seen_pixels);
  return s;
}

std::string FormatSourcePixels(const SourcePixelShares& s) {
  char buffer[200];
  std::snprintf(buffer, sizeof buffer,
                "in the sources' pixels: <1 px: %.4f  <2 px: %.4f; 2 %% of depth moves the match "
                ">= 1 px: %.4f  >= 0.5 px: %.4f",
                s.within_1px, s.within_2px, s.moves_1px, s.moves_half_px);
  return buffer;
}

}  // namespace dispmvs::train
