#include "model/confident_plane_fill.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "model/geometry.h"
#include "model/nearest_plane.h"

namespace dispmvs::model {

void ConfidentPlaneFillOptions::Check() const {
  const auto fail = [](const std::string& what) {
    throw std::invalid_argument("confident plane fill: " + what);
  };
  if (!(below >= 0 && below < 1)) fail("below must be in [0, 1)");
  if (!(anchor > below && anchor <= 1)) fail("anchor must be in (below, 1]");
  if (slope_radius < 1 || slope_radius > 64) fail("slope_radius must be in [1, 64]");
  if (!(max_change >= 0 && std::isfinite(max_change))) fail("max_change must be >= 0 (0: any change)");
}

ConfidentPlaneFill FillFromConfidentPlanes(const torch::Tensor& depth, const torch::Tensor& confidence,
                                           const ConfidentPlaneFillOptions& options) {
  options.Check();
  if (!depth.defined() || depth.dim() != 4 || depth.size(1) != 1) {
    throw std::invalid_argument("FillFromConfidentPlanes: depth must be [B,1,H,W]");
  }
  if (!confidence.defined() || confidence.sizes() != depth.sizes()) {
    throw std::invalid_argument("FillFromConfidentPlanes: confidence must be depth's shape");
  }
  torch::NoGradGuard no_grad;
  const torch::Tensor d = depth.to(torch::kFloat32);
  const torch::Tensor c = confidence.to(d.options());
  const torch::Tensor has = (d > 0) & torch::isfinite(d);
  const torch::Tensor w = torch::where(has, d.reciprocal(), torch::zeros_like(d));
  const torch::Tensor anchor = has & (c >= options.anchor);
  // Within the inverse depths of the map's own pixels.
  const auto [low, high] = InverseDepthBounds(w, has);
  const torch::Tensor w_filled = ExtendTrustedPlanes(w, anchor, options.slope_radius, low, high, options.max_change);
  ConfidentPlaneFill result;
  result.filled = has & (c < options.below) & (w_filled > 0);
  result.depth = torch::where(result.filled, w_filled.reciprocal(), d).to(depth.scalar_type());
  return result;
}

}  // namespace dispmvs::model
