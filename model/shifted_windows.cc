#include "model/shifted_windows.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <stdexcept>

namespace dispmvs::model {
namespace {

void CheckInputs(const torch::Tensor& score, int64_t shift) {
  if (score.dim() != 4 || score.size(1) != 1 || !score.is_floating_point()) {
    throw std::invalid_argument("BestOfShiftedWindows: score must be a [B,1,H,W] floating-point tensor");
  }
  if (shift < 0) throw std::invalid_argument("BestOfShiftedWindows: shift must be >= 0");
}

}  // namespace

torch::Tensor BestOfShiftedWindowsByOps(const torch::Tensor& score, int64_t shift) {
  CheckInputs(score, shift);
  if (shift == 0) return score;
  torch::Tensor best = score.clone();
  // Along each axis, the map against its copy moved by the shift either way,
  // where they overlap; pixels whose shifted window leaves the image keep
  // what they have.
  const auto compare_along = [&](int64_t dim) {
    const int64_t overlap = score.size(dim) - shift;
    if (overlap <= 0) return;
    torch::Tensor from_after = best.narrow(dim, 0, overlap), from_before = best.narrow(dim, shift, overlap);
    from_after.copy_(torch::maximum(from_after, score.narrow(dim, shift, overlap)));
    from_before.copy_(torch::maximum(from_before, score.narrow(dim, 0, overlap)));
  };
  compare_along(3);
  compare_along(2);
  return best;
}

torch::Tensor BestOfShiftedWindows(const torch::Tensor& score, int64_t shift) {
  CheckInputs(score, shift);
  // Without shifts, nothing to compare: the refinement's scores pass
  // through as they were before the shifts, at no cost.
  if (shift == 0) return score;
  if (!score.device().is_cpu() || score.scalar_type() != torch::kFloat32) {
    return BestOfShiftedWindowsByOps(score, shift);
  }
  // On the CPU one pass over the map instead of eight full-size operations:
  // the refinement scores some thirty surfaces per view.
  const torch::Tensor in = score.contiguous();
  torch::Tensor best = torch::empty_like(in);
  const int64_t h = in.size(2), w = in.size(3), rows = in.size(0) * h;
  const float* s = in.data_ptr<float>();
  float* out = best.data_ptr<float>();
  at::parallel_for(0, rows, 16, [&](int64_t begin, int64_t end) {
    for (int64_t row = begin; row < end; ++row) {
      const int64_t y = row % h;
      const float* line = s + row * w;
      for (int64_t x = 0; x < w; ++x) {
        float m = line[x];
        if (x + shift < w) m = std::max(m, line[x + shift]);
        if (x - shift >= 0) m = std::max(m, line[x - shift]);
        if (y + shift < h) m = std::max(m, line[x + shift * w]);
        if (y - shift >= 0) m = std::max(m, line[x - shift * w]);
        out[row * w + x] = m;
      }
    }
  });
  return best;
}

}  // namespace dispmvs::model
