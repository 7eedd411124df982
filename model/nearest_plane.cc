#include "model/nearest_plane.h"

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/propagation_planes.h"

namespace dispmvs::model {
namespace {

void Fail(const std::string& what) { throw std::invalid_argument(what); }

bool IsMap(const torch::Tensor& t) { return t.defined() && t.dim() == 4 && t.size(1) == 1; }

}  // namespace

torch::Tensor NearestAnchor(const torch::Tensor& anchor) {
  if (!IsMap(anchor) || anchor.scalar_type() != torch::kBool) {
    Fail("NearestAnchor: anchor must be [B,1,H,W] bool");
  }
  const int64_t b = anchor.size(0), h = anchor.size(2), w = anchor.size(3), plane = h * w;
  const torch::Tensor mask = anchor.to(torch::kCPU).contiguous();
  torch::Tensor nearest = torch::full({b, 1, h, w}, -1, torch::TensorOptions().dtype(torch::kLong));
  const bool* m = mask.data_ptr<bool>();
  int64_t* out = nearest.data_ptr<int64_t>();
  std::vector<int64_t> queue(static_cast<size_t>(plane));
  for (int64_t item = 0; item < b; ++item) {
    const bool* mi = m + item * plane;
    int64_t* oi = out + item * plane;
    // Breadth first from every anchor at once: each pixel is reached first
    // from (one of) its nearest anchors, in O(H W).
    int64_t head = 0, tail = 0;
    for (int64_t p = 0; p < plane; ++p) {
      if (mi[p]) {
        oi[p] = p;
        queue[static_cast<size_t>(tail++)] = p;
      }
    }
    while (head < tail) {
      const int64_t p = queue[static_cast<size_t>(head++)];
      const int64_t py = p / w, px = p % w;
      for (int64_t dy = -1; dy <= 1; ++dy) {
        for (int64_t dx = -1; dx <= 1; ++dx) {
          const int64_t y = py + dy, x = px + dx;
          if (y < 0 || y >= h || x < 0 || x >= w) continue;
          const int64_t q = y * w + x;
          if (oi[q] >= 0) continue;
          oi[q] = oi[p];
          queue[static_cast<size_t>(tail++)] = q;
        }
      }
    }
  }
  return nearest.to(anchor.device());
}

torch::Tensor ExtendNearestPlane(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                 const torch::Tensor& nearest) {
  if (!IsMap(w) || gx.sizes() != w.sizes() || gy.sizes() != w.sizes() || !nearest.defined() ||
      nearest.sizes() != w.sizes() || nearest.scalar_type() != torch::kLong) {
    Fail("ExtendNearestPlane: w, gx, gy and nearest (long) must be the same [B,1,H,W]");
  }
  const int64_t b = w.size(0), h = w.size(2), wd = w.size(3);
  const torch::Tensor has = nearest >= 0;
  const torch::Tensor index = torch::where(has, nearest, torch::zeros_like(nearest)).view({b, 1, h * wd});
  const auto at_nearest = [&](const torch::Tensor& t) {
    return t.reshape({b, 1, h * wd}).gather(2, index).view({b, 1, h, wd});
  };
  const torch::Tensor column = torch::arange(wd, w.options()).view({1, 1, 1, wd});
  const torch::Tensor row = torch::arange(h, w.options()).view({1, 1, h, 1});
  const torch::Tensor qx = (torch::remainder(nearest, wd)).to(w.scalar_type());
  const torch::Tensor qy = torch::div(nearest, wd, "floor").to(w.scalar_type());
  const torch::Tensor extended = at_nearest(w) + at_nearest(gx) * (column - qx) + at_nearest(gy) * (row - qy);
  return torch::where(has, extended, torch::zeros_like(extended));
}

torch::Tensor ExtendTrustedPlanes(const torch::Tensor& w, const torch::Tensor& trusted, int64_t slope_radius,
                                  const torch::Tensor& low, const torch::Tensor& high, double max_change) {
  const auto [gx, gy] = LeastSquaresSlopes(w, trusted, slope_radius);
  const torch::Tensor nearest = NearestAnchor(trusted);
  const torch::Tensor extended = ExtendNearestPlane(w, gx, gy, nearest);
  const torch::Tensor bounded = torch::minimum(torch::maximum(extended, low), high);
  torch::Tensor keep = (nearest >= 0) & (extended > 0);
  if (max_change > 0) {
    const torch::Tensor has = w > 0;
    keep &= ~has | ((bounded / torch::where(has, w, torch::ones_like(w)) - 1).abs() <= max_change);
  }
  return torch::where(keep, bounded, torch::zeros_like(w));
}

}  // namespace dispmvs::model
