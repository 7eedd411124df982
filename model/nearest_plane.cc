#include "model/nearest_plane.h"

#include <ATen/Parallel.h>

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/propagation_planes.h"

namespace dispmvs::model {
namespace {

void Fail(const std::string& what) { throw std::invalid_argument(what); }

bool IsMap(const torch::Tensor& t) { return t.defined() && t.dim() == 4 && t.size(1) == 1; }

void CheckExtendInputs(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                       const torch::Tensor& nearest) {
  if (!IsMap(w) || gx.sizes() != w.sizes() || gy.sizes() != w.sizes() || !nearest.defined() ||
      nearest.sizes() != w.sizes() || nearest.scalar_type() != torch::kLong) {
    Fail("ExtendNearestPlane: w, gx, gy and nearest (long) must be the same [B,1,H,W]");
  }
}

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

std::array<torch::Tensor, 4> NearestAnchorsAlongAxes(const torch::Tensor& anchor) {
  if (!IsMap(anchor) || anchor.scalar_type() != torch::kBool) {
    Fail("NearestAnchorsAlongAxes: anchor must be [B,1,H,W] bool");
  }
  const int64_t b = anchor.size(0), h = anchor.size(2), w = anchor.size(3), plane = h * w;
  const torch::Tensor mask = anchor.to(torch::kCPU).contiguous();
  const bool* m = mask.data_ptr<bool>();
  std::array<torch::Tensor, 4> nearest;
  std::array<int64_t*, 4> out{};
  for (size_t side = 0; side < 4; ++side) {
    nearest[side] = torch::empty({b, 1, h, w}, torch::TensorOptions().dtype(torch::kLong));
    out[side] = nearest[side].data_ptr<int64_t>();
  }
  // One scan per side along each row or column, carrying the last anchor
  // passed: the line's pixels from `first` in steps of `step`.
  const auto scan = [&](int64_t item, size_t side, int64_t first, int64_t step, int64_t count) {
    const bool* mi = m + item * plane;
    int64_t* oi = out[side] + item * plane;
    int64_t last = -1;
    for (int64_t k = 0, p = first; k < count; ++k, p += step) {
      if (mi[p]) last = p;
      oi[p] = last;
    }
  };
  at::parallel_for(0, b, 1, [&](int64_t begin, int64_t end) {
    for (int64_t item = begin; item < end; ++item) {
      for (int64_t y = 0; y < h; ++y) {
        scan(item, 0, y * w, 1, w);
        scan(item, 1, y * w + w - 1, -1, w);
      }
      for (int64_t x = 0; x < w; ++x) {
        scan(item, 2, x, w, h);
        scan(item, 3, (h - 1) * w + x, -w, h);
      }
    }
  });
  for (auto& t : nearest) t = t.to(anchor.device());
  return nearest;
}

torch::Tensor ExtendNearestPlaneByOps(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                      const torch::Tensor& nearest) {
  CheckExtendInputs(w, gx, gy, nearest);
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

torch::Tensor ExtendNearestPlane(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                 const torch::Tensor& nearest) {
  CheckExtendInputs(w, gx, gy, nearest);
  const auto cpu_float = [](const torch::Tensor& t) {
    return t.device().is_cpu() && t.scalar_type() == torch::kFloat32;
  };
  if (!cpu_float(w) || !cpu_float(gx) || !cpu_float(gy) || !nearest.device().is_cpu()) {
    return ExtendNearestPlaneByOps(w, gx, gy, nearest);
  }
  // A gather of three maps and an affine step per pixel: one pass instead
  // of some fifteen full-size operations (5-9 ms at 640x480 as operations).
  const torch::Tensor wc = w.contiguous(), gxc = gx.contiguous(), gyc = gy.contiguous(), nc = nearest.contiguous();
  const int64_t b = w.size(0), h = w.size(2), wd = w.size(3), plane = h * wd;
  torch::Tensor out = torch::empty_like(wc);
  const float* w_p = wc.data_ptr<float>();
  const float* gx_p = gxc.data_ptr<float>();
  const float* gy_p = gyc.data_ptr<float>();
  const int64_t* n_p = nc.data_ptr<int64_t>();
  float* o_p = out.data_ptr<float>();
  at::parallel_for(0, b * h, 16, [&](int64_t begin, int64_t end) {
    for (int64_t task = begin; task < end; ++task) {
      const int64_t item = task / h, y = task % h, base = item * plane;
      for (int64_t x = 0; x < wd; ++x) {
        const int64_t p = base + y * wd + x, q = n_p[p];
        if (q < 0) {
          o_p[p] = 0.0f;
          continue;
        }
        const int64_t qx = q % wd, qy = q / wd;
        // As the operations round: (w + gx dx) + gy dy, each in float.
        o_p[p] = (w_p[base + q] + gx_p[base + q] * static_cast<float>(x - qx)) +
                 gy_p[base + q] * static_cast<float>(y - qy);
      }
    }
  });
  return out;
}

torch::Tensor ExtendNearestPlaneWithin(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                       const torch::Tensor& nearest, const torch::Tensor& low,
                                       const torch::Tensor& high) {
  const torch::Tensor extended = ExtendNearestPlane(w, gx, gy, nearest);
  const torch::Tensor bounded = torch::minimum(torch::maximum(extended, low), high);
  // ExtendNearestPlane is 0 where nearest is -1: "positive" covers both.
  return torch::where(extended > 0, bounded, torch::zeros_like(extended));
}

torch::Tensor ExtendTrustedPlanes(const torch::Tensor& w, const torch::Tensor& trusted, int64_t slope_radius,
                                  const torch::Tensor& low, const torch::Tensor& high, double max_change) {
  const auto [gx, gy] = LeastSquaresSlopes(w, trusted, slope_radius);
  const torch::Tensor bounded = ExtendNearestPlaneWithin(w, gx, gy, NearestAnchor(trusted), low, high);
  if (max_change <= 0) return bounded;
  const torch::Tensor has = w > 0;
  const torch::Tensor near_own =
      ~has | ((bounded / torch::where(has, w, torch::ones_like(w)) - 1).abs() <= max_change);
  return torch::where(near_own, bounded, torch::zeros_like(w));
}

}  // namespace dispmvs::model
