#include "model/window_mean.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <stdexcept>
#include <vector>

namespace dispmvs::model {
namespace {

// 1 / (number of indices of [i - r, i + r] inside [0, n - 1]) for every i.
std::vector<double> InverseCounts(int64_t n, int64_t r) {
  std::vector<double> inverse(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) {
    const int64_t count = std::min(i + r, n - 1) - std::max<int64_t>(i - r, 0) + 1;
    inverse[static_cast<size_t>(i)] = 1.0 / static_cast<double>(count);
  }
  return inverse;
}

// One plane: row sums into `rows`, then a running column sum over them.
// Sums are kept in double so that adding and removing values along a line
// of thousands of pixels leaves no drift.
void WindowMeanPlane(const float* in, float* out, int64_t h, int64_t w, int64_t r,
                     const std::vector<double>& inverse_rows,
                     const std::vector<double>& inverse_cols, std::vector<double>& rows,
                     std::vector<double>& column_sums) {
  for (int64_t i = 0; i < h; ++i) {
    const float* line = in + i * w;
    double* sums = rows.data() + i * w;
    double s = 0;
    for (int64_t j = 0; j <= std::min(r, w - 1); ++j) s += line[j];
    for (int64_t j = 0; j < w; ++j) {
      sums[j] = s;
      if (j + r + 1 < w) s += line[j + r + 1];
      if (j - r >= 0) s -= line[j - r];
    }
  }
  std::fill(column_sums.begin(), column_sums.end(), 0.0);
  for (int64_t i = 0; i <= std::min(r, h - 1); ++i) {
    const double* sums = rows.data() + i * w;
    for (int64_t j = 0; j < w; ++j) column_sums[j] += sums[j];
  }
  for (int64_t i = 0; i < h; ++i) {
    float* line = out + i * w;
    const double row_scale = inverse_rows[static_cast<size_t>(i)];
    for (int64_t j = 0; j < w; ++j) {
      line[j] = static_cast<float>(column_sums[j] * row_scale * inverse_cols[static_cast<size_t>(j)]);
    }
    if (i + r + 1 < h) {
      const double* add = rows.data() + (i + r + 1) * w;
      for (int64_t j = 0; j < w; ++j) column_sums[j] += add[j];
    }
    if (i - r >= 0) {
      const double* remove = rows.data() + (i - r) * w;
      for (int64_t j = 0; j < w; ++j) column_sums[j] -= remove[j];
    }
  }
}

torch::Tensor WindowMeanCpu(const torch::Tensor& x, int64_t r) {
  const torch::Tensor in = x.contiguous();
  const int64_t planes = in.size(0) * in.size(1), h = in.size(2), w = in.size(3);
  torch::Tensor out = torch::empty_like(in);
  const std::vector<double> inverse_rows = InverseCounts(h, r), inverse_cols = InverseCounts(w, r);
  const float* in_p = in.data_ptr<float>();
  float* out_p = out.data_ptr<float>();
  at::parallel_for(0, planes, 1, [&](int64_t begin, int64_t end) {
    std::vector<double> rows(static_cast<size_t>(h * w)), column_sums(static_cast<size_t>(w));
    for (int64_t p = begin; p < end; ++p) {
      WindowMeanPlane(in_p + p * h * w, out_p + p * h * w, h, w, r, inverse_rows, inverse_cols,
                      rows, column_sums);
    }
  });
  return out;
}

// Sum of shifted slices of the zero-padded image, divided by the counts.
torch::Tensor WindowMeanSlices(const torch::Tensor& x, int64_t r) {
  namespace F = torch::nn::functional;
  const int64_t h = x.size(2), w = x.size(3);
  const torch::Tensor padded = F::pad(x, F::PadFuncOptions({r, r, r, r}));
  torch::Tensor rows = padded.narrow(3, 0, w).clone();
  for (int64_t k = 1; k <= 2 * r; ++k) rows += padded.narrow(3, k, w);
  torch::Tensor sums = rows.narrow(2, 0, h).clone();
  for (int64_t k = 1; k <= 2 * r; ++k) sums += rows.narrow(2, k, h);
  const torch::TensorOptions opts = x.options();
  const torch::Tensor inverse_rows =
      torch::tensor(InverseCounts(h, r), torch::kFloat64).to(opts).view({1, 1, h, 1});
  const torch::Tensor inverse_cols =
      torch::tensor(InverseCounts(w, r), torch::kFloat64).to(opts).view({1, 1, 1, w});
  return sums * inverse_rows * inverse_cols;
}

}  // namespace

torch::Tensor WindowMean(const torch::Tensor& x, int64_t radius) {
  if (!x.defined() || x.dim() != 4 || x.size(2) < 1 || x.size(3) < 1) {
    throw std::invalid_argument("WindowMean: x must be [B,C,H,W] with H, W >= 1");
  }
  if (radius < 0) throw std::invalid_argument("WindowMean: radius must be >= 0");
  if (x.numel() == 0) return torch::empty_like(x);
  if (x.device().is_cpu() && x.scalar_type() == torch::kFloat32) return WindowMeanCpu(x, radius);
  return WindowMeanSlices(x, radius);
}

}  // namespace dispmvs::model
