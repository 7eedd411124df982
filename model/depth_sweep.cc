#include "model/depth_sweep.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "model/geometry.h"
#include "model/surface_ncc.h"
#include "model/window_mean.h"

namespace dispmvs::model {
namespace {

void CheckSweepInputs(const torch::Tensor& source, const torch::Tensor& reference,
                      const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                      const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& start,
                      const torch::Tensor& usable, int64_t radius, int64_t max_hypotheses, double step_pixels) {
  const auto fail = [](const std::string& what) { throw std::invalid_argument("SweepInverseDepth: " + what); };
  if (!start.defined() || start.dim() != 4 || start.size(1) != 1) fail("start must be [B,1,H,W]");
  const torch::IntArrayRef shape = start.sizes();
  for (const torch::Tensor* t : {&source, &reference, &reference_mean, &reference_var}) {
    if (!t->defined() || t->sizes() != shape) fail("images and window statistics must be start's shape [B,1,H,W]");
  }
  if (!usable.defined() || usable.sizes() != shape || usable.scalar_type() != torch::kBool) {
    fail("usable must be a bool [B,1,H,W]");
  }
  const int64_t n = shape[0], h = shape[2], w = shape[3];
  if (!a.defined() || a.sizes() != torch::IntArrayRef({n, 3, h, w})) fail("a must be [B,3,H,W]");
  if (!b.defined() || b.dim() != 4 || b.size(0) != n || b.size(1) != 3) fail("b must be [B,3,H,W] or [B,3,1,1]");
  if (radius < 1) fail("radius must be >= 1");
  if (max_hypotheses < 0) fail("max_hypotheses must be >= 0");
  if (!(step_pixels > 0) || !std::isfinite(step_pixels)) fail("step_pixels must be > 0");
}

}  // namespace

torch::Tensor WindowMedianLevel(const torch::Tensor& levels, const torch::Tensor& mask, int64_t count,
                                int64_t radius) {
  if (!levels.defined() || levels.dim() != 4 || levels.size(1) != 1 || levels.scalar_type() != torch::kLong) {
    throw std::invalid_argument("WindowMedianLevel: levels must be a long [B,1,H,W]");
  }
  if (!mask.defined() || mask.sizes() != levels.sizes() || mask.scalar_type() != torch::kBool) {
    throw std::invalid_argument("WindowMedianLevel: mask must be a bool of levels' shape");
  }
  if (radius < 0 || count < 0) throw std::invalid_argument("WindowMedianLevel: radius and count must be >= 0");
  const torch::Tensor counted = mask.to(torch::kFloat32);
  // Window means of 0/1 maps are exact multiples of 1 / (window pixels
  // inside the image): a quarter of the smallest such share absorbs their
  // rounding.
  const double tolerance = 0.25 / static_cast<double>((2 * radius + 1) * (2 * radius + 1));
  const torch::Tensor share = WindowMean(counted, radius);
  const torch::Tensor half = 0.5 * share - tolerance;
  torch::Tensor median = torch::full_like(levels, -1);
  torch::Tensor found = share <= 0;  // no counted pixel: stays -1
  for (int64_t level = 0; level < count && !found.all().item<bool>(); ++level) {
    const torch::Tensor at_or_below = counted * (levels <= level).to(torch::kFloat32);
    const torch::Tensor reached = ~found & (WindowMean(at_or_below, radius) >= half);
    median.masked_fill_(reached, level);
    found = found | reached;
  }
  return median;
}

torch::Tensor SweepInverseDepth(const torch::Tensor& source, const torch::Tensor& reference,
                                const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                                const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& start,
                                const torch::Tensor& usable, int64_t radius, int64_t max_hypotheses,
                                double step_pixels) {
  CheckSweepInputs(source, reference, reference_mean, reference_var, a, b, start, usable, radius, max_hypotheses,
                   step_pixels);
  torch::NoGradGuard no_grad;
  const torch::Tensor none = torch::zeros_like(start);
  const torch::Tensor have = usable & (start > 0) & torch::isfinite(start);
  // The range: the start's inverse depths, per batch item.
  const auto [low, high] = InverseDepthBounds(start, have);
  // How far the match moves per unit of inverse depth at the start: its
  // median over the usable pixels that have one sets the spacing.
  const torch::Tensor rate = MatchShiftPerInverseDepth(EpipolarPair{a, b}, start);
  const torch::Tensor counts_rate = have & (rate > 0);
  int64_t count = 0;
  for (int64_t item = 0; item < start.size(0); ++item) {
    const torch::Tensor rates = rate[item].masked_select(counts_rate[item]);
    if (rates.numel() == 0) continue;
    const double pixels = (high[item] - low[item]).item<double>() * rates.median().item<double>();
    if (std::isfinite(pixels)) count = std::max<int64_t>(count, static_cast<int64_t>(std::ceil(pixels / step_pixels)));
  }
  count = std::min(count, max_hypotheses);
  if (count < 2) return none;

  const torch::Tensor weights = have.to(start.scalar_type());
  const double margin = static_cast<double>(radius);
  const torch::Tensor span = torch::where(high > low, high - low, torch::zeros_like(high));
  torch::Tensor best = torch::zeros_like(start, torch::kLong);
  torch::Tensor best_score = torch::full_like(start, -2.0);
  // Hypothesis k (a float tensor: [B,1,H,W] of levels, or one level).
  const auto hypothesis = [&](const torch::Tensor& k) {
    return low + span * ((k + 0.5) / static_cast<double>(count));
  };
  for (int64_t k = 0; k < count; ++k) {
    // The constant surface where usable, 0 (none) elsewhere.
    const torch::Tensor surface =
        weights * hypothesis(torch::full({1, 1, 1, 1}, static_cast<double>(k), start.options()));
    const torch::Tensor score = WindowMean(
        ScoreAlongSurface(source, reference, reference_mean, reference_var, a, b, surface, weights, radius, margin),
        kSweepAggregationRadius);
    best.masked_fill_(score > best_score, k);
    best_score = torch::maximum(score, best_score);
  }
  // The median of the winners' levels (the hypotheses are monotonic in k),
  // over the usable pixels of each window.
  const torch::Tensor median = WindowMedianLevel(best, have, count, kSweepMedianRadius);
  return torch::where(have & (median >= 0), hypothesis(median.to(start.scalar_type())), none);
}

}  // namespace dispmvs::model
