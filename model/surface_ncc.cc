#include "model/surface_ncc.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/window_mean.h"

namespace dispmvs::model {
namespace {

namespace F = torch::nn::functional;

void CheckShapes(const torch::Tensor& source, const torch::Tensor& reference,
                 const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                 const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface) {
  const auto fail = [](const std::string& what) {
    throw std::invalid_argument("CorrelateAlongSurface: " + what);
  };
  if (!source.defined() || source.dim() != 4 || source.size(1) != 1) fail("source must be [B*N,1,H,W]");
  const auto planes = source.sizes();
  for (const torch::Tensor* t : {&reference, &reference_mean, &reference_var}) {
    if (!t->defined() || t->sizes() != planes) fail("the reference tensors must be source's shape");
  }
  const std::vector<int64_t> pair_shape = {source.size(0), 3, source.size(2), source.size(3)};
  const std::vector<int64_t> constant_shape = {source.size(0), 3, 1, 1};
  if (!a.defined() || a.sizes() != torch::IntArrayRef(pair_shape) || !b.defined() ||
      (b.sizes() != a.sizes() && b.sizes() != torch::IntArrayRef(constant_shape))) {
    fail("a must be [B*N,3,H,W] and b [B*N,3,H,W] or [B*N,3,1,1]");
  }
  if (!surface.defined() || surface.dim() != 4 || surface.size(1) != 1 || surface.size(0) < 1 ||
      source.size(0) % surface.size(0) != 0 || surface.size(2) != source.size(2) ||
      surface.size(3) != source.size(3)) {
    fail("surface must be [B,1,H,W] with B dividing source's B*N");
  }
}

// Whether every tensor is a CPU float32 one: what the hand-written passes take.
bool AllCpuFloat(std::initializer_list<const torch::Tensor*> tensors) {
  for (const torch::Tensor* t : tensors) {
    if (!t->device().is_cpu() || t->scalar_type() != torch::kFloat32) return false;
  }
  return true;
}

void CheckWeights(const torch::Tensor& weights, const torch::Tensor& source, const torch::Tensor& surface) {
  const int64_t n = source.size(0) / surface.size(0);
  if (!weights.defined() ||
      weights.sizes() != torch::IntArrayRef({surface.size(0), n, source.size(2), source.size(3)})) {
    throw std::invalid_argument("ScoreAlongSurface: weights must be [B,N,H,W]");
  }
}

// One source plane's sampling: where reference pixel p, at inverse depth
// surface[p], falls in the source (bilinear, zero outside the image, as
// grid_sample with align_corners), and whether the match counts.
struct PlaneSampler {
  const float* source;
  const float* a;  // [3,H,W]
  const float* b;  // [3,H,W] or [3]
  const float* surface;
  int64_t h, w;
  bool b_per_pixel;
  float half_w, half_h, limit_x, limit_y;

  float Sample(int64_t p, bool* inside) const {
    const int64_t hw = h * w;
    const int64_t q = b_per_pixel ? p : 0, b_channel = b_per_pixel ? hw : 1;
    const float inverse_depth = surface[p];
    const float px = a[p] + inverse_depth * b[q];
    const float py = a[hw + p] + inverse_depth * b[b_channel + q];
    const float pz = a[2 * hw + p] + inverse_depth * b[2 * b_channel + q];
    const bool in_front = pz > 0 && inverse_depth > 0;
    // Behind the source the match is taken as pixel (0, 0), as the
    // operations' path does; it does not count, but it is in its
    // neighbours' windows all the same.
    const float inverse_z = in_front ? 1.0f / pz : 0.0f;
    const float x = px * inverse_z, y = py * inverse_z;
    *inside = in_front && std::abs(x - half_w) <= limit_x && std::abs(y - half_h) <= limit_y;
    // Beyond [-1, w) x [-1, h) no pixel of the image is in reach (and NaN or
    // infinite coordinates fail the comparisons).
    if (!(x >= -1.0f && y >= -1.0f && x < static_cast<float>(w) && y < static_cast<float>(h))) return 0.0f;
    // floor by truncation, exact in this range: std::floor is a library call
    // on x86-64's baseline instruction set, twice per sample.
    int64_t x0 = static_cast<int64_t>(x), y0 = static_cast<int64_t>(y);
    x0 -= static_cast<float>(x0) > x;
    y0 -= static_cast<float>(y0) > y;
    const float fx = x - static_cast<float>(x0), fy = y - static_cast<float>(y0);
    if (x0 >= 0 && y0 >= 0 && x0 + 1 < w && y0 + 1 < h) {
      const float* row = source + y0 * w + x0;
      return (1 - fy) * ((1 - fx) * row[0] + fx * row[1]) + fy * ((1 - fx) * row[w] + fx * row[w + 1]);
    }
    const auto at = [&](int64_t yy, int64_t xx) {
      return (xx >= 0 && xx < w && yy >= 0 && yy < h) ? source[yy * w + xx] : 0.0f;
    };
    return (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1)) +
           fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1));
  }
};

// Rows [row_begin, row_end) of one source plane in one streaming pass: rows
// are sampled as the window reaches them (from row_begin - r) into a ring of
// 2r + 2 rows, column sums of v, v^2 and reference * v move down with the
// window (in double, so that adding and removing 2r + 1 rows at a time
// leaves no drift), and each output row's window sums are a running sum
// along those columns. Nothing of full size is written but the NCC and the
// flags; ncc and ok point at row_begin's first pixel.
// `needed` (null: every pixel), like ncc from row_begin: the pixels whose NCC
// is wanted; the others get ncc 0, ok false without the arithmetic.
void CorrelateRows(const PlaneSampler& sampler, const float* reference, const float* reference_mean,
                   const float* reference_var, int64_t r, int64_t row_begin, int64_t row_end, float* ncc,
                   bool* ok, const float* needed) {
  const int64_t h = sampler.h, w = sampler.w;
  const int64_t ring = 2 * r + 2;
  std::vector<float> values(static_cast<size_t>(ring * w));
  std::vector<char> inside(static_cast<size_t>(ring * w));
  std::vector<double> columns(static_cast<size_t>(3 * w), 0.0);
  double* col_v = columns.data();
  double* col_vv = col_v + w;
  double* col_rv = col_vv + w;
  // Adds (sign +1) or removes (-1) row k of the ring to the column sums;
  // sampling it first when it comes in.
  const auto take_row = [&](int64_t k, double sign) {
    float* v = values.data() + (k % ring) * w;
    const float* ref_row = reference + k * w;
    if (sign > 0) {
      char* in = inside.data() + (k % ring) * w;
      for (int64_t j = 0; j < w; ++j) {
        bool is_inside = false;
        v[j] = sampler.Sample(k * w + j, &is_inside);
        in[j] = is_inside;
      }
    }
    for (int64_t j = 0; j < w; ++j) {
      const double value = v[j];
      col_v[j] += sign * value;
      col_vv[j] += sign * static_cast<double>(v[j] * v[j]);
      col_rv[j] += sign * static_cast<double>(ref_row[j] * v[j]);
    }
  };
  // 1 / (window columns inside the image) per column: the window's pixel
  // count is that times the rows', without a division per pixel.
  std::vector<double> inverse_cols(static_cast<size_t>(w));
  for (int64_t j = 0; j < w; ++j) {
    inverse_cols[static_cast<size_t>(j)] =
        1.0 / static_cast<double>(std::min(j + r, w - 1) - std::max<int64_t>(j - r, 0) + 1);
  }
  for (int64_t k = std::max<int64_t>(row_begin - r, 0); k <= std::min(row_begin + r, h - 1); ++k) take_row(k, 1.0);
  for (int64_t i = row_begin; i < row_end; ++i) {
    const int64_t rows = std::min(i + r, h - 1) - std::max<int64_t>(i - r, 0) + 1;
    const double inverse_rows = 1.0 / static_cast<double>(rows);
    const char* in = inside.data() + (i % ring) * w;
    float* ncc_row = ncc + (i - row_begin) * w;
    bool* ok_row = ok + (i - row_begin) * w;
    const float* needed_row = needed ? needed + (i - row_begin) * w : nullptr;
    double s_v = 0, s_vv = 0, s_rv = 0;
    for (int64_t j = 0; j <= std::min(r, w - 1); ++j) {
      s_v += col_v[j];
      s_vv += col_vv[j];
      s_rv += col_rv[j];
    }
    for (int64_t j = 0; j < w; ++j) {
      if (needed_row == nullptr || needed_row[j] != 0) {
        const double inverse_count = inverse_rows * inverse_cols[static_cast<size_t>(j)];
        const int64_t p = i * w + j;
        const float s_mean = static_cast<float>(s_v * inverse_count);
        const float s_var = std::max(static_cast<float>(s_vv * inverse_count) - s_mean * s_mean, 0.0f);
        const float covariance = static_cast<float>(s_rv * inverse_count) - reference_mean[p] * s_mean;
        ncc_row[j] = covariance / std::sqrt(std::max(reference_var[p] * s_var, 1e-12f));
        ok_row[j] = in[j] && s_var > 1e-10f;
      } else {
        ncc_row[j] = 0.0f;
        ok_row[j] = false;
      }
      if (j + r + 1 < w) {
        s_v += col_v[j + r + 1];
        s_vv += col_vv[j + r + 1];
        s_rv += col_rv[j + r + 1];
      }
      if (j - r >= 0) {
        s_v -= col_v[j - r];
        s_vv -= col_vv[j - r];
        s_rv -= col_rv[j - r];
      }
    }
    if (i + r + 1 < h) take_row(i + r + 1, 1.0);
    if (i - r >= 0) take_row(i - r, -1.0);
  }
}

// The CPU loops split every plane into bands of this many rows, so that
// two-view workspaces (one source plane) use every thread too. Fixed, not
// derived from the thread count: a band's sums start afresh at its first
// row, and the results stay the same whatever the number of threads. Each
// band samples 2r rows more than it outputs (6 of 64 at r = 3).
constexpr int64_t kBandRows = 64;

int64_t BandCount(int64_t h) { return (h + kBandRows - 1) / kBandRows; }

// Everything the CPU loops read, contiguous, and the sampler of plane i.
struct CpuPlanes {
  torch::Tensor src, ref, mean, var, a, b, surface;
  int64_t planes, n, h, w;
  bool b_per_pixel;
  float half_w, half_h;
  double margin;

  CpuPlanes(const torch::Tensor& source, const torch::Tensor& reference, const torch::Tensor& reference_mean,
            const torch::Tensor& reference_var, const torch::Tensor& a_in, const torch::Tensor& b_in,
            const torch::Tensor& surface_in, double margin_in)
      : src(source.contiguous()),
        ref(reference.contiguous()),
        mean(reference_mean.contiguous()),
        var(reference_var.contiguous()),
        a(a_in.contiguous()),
        b(b_in.contiguous()),
        surface(surface_in.contiguous()),
        planes(source.size(0)),
        n(source.size(0) / surface_in.size(0)),
        h(source.size(2)),
        w(source.size(3)),
        b_per_pixel(b_in.size(2) == source.size(2) && b_in.size(3) == source.size(3) &&
                    source.size(2) * source.size(3) > 1),
        half_w(0.5f * static_cast<float>(source.size(3) - 1)),
        half_h(0.5f * static_cast<float>(source.size(2) - 1)),
        margin(margin_in) {}

  PlaneSampler Sampler(int64_t i) const {
    const int64_t hw = h * w;
    return PlaneSampler{src.data_ptr<float>() + i * hw,
                        a.data_ptr<float>() + i * 3 * hw,
                        b.data_ptr<float>() + i * (b_per_pixel ? 3 * hw : 3),
                        surface.data_ptr<float>() + (i / n) * hw,
                        h,
                        w,
                        b_per_pixel,
                        half_w,
                        half_h,
                        half_w - static_cast<float>(margin),
                        half_h - static_cast<float>(margin)};
  }

  void Correlate(int64_t i, int64_t radius, int64_t row_begin, int64_t row_end, float* ncc, bool* ok,
                 const float* needed = nullptr) const {
    const int64_t hw = h * w;
    CorrelateRows(Sampler(i), ref.data_ptr<float>() + i * hw, mean.data_ptr<float>() + i * hw,
                  var.data_ptr<float>() + i * hw, radius, row_begin, row_end, ncc, ok, needed);
  }
};

SurfaceCorrelation CorrelateAlongSurfaceCpu(const torch::Tensor& source, const torch::Tensor& reference,
                                            const torch::Tensor& reference_mean,
                                            const torch::Tensor& reference_var, const torch::Tensor& a,
                                            const torch::Tensor& b, const torch::Tensor& surface,
                                            int64_t radius, double margin) {
  const CpuPlanes in(source, reference, reference_mean, reference_var, a, b, surface, margin);
  const int64_t hw = in.h * in.w, bands = BandCount(in.h);
  SurfaceCorrelation result;
  result.ncc = torch::empty({in.planes, 1, in.h, in.w}, source.options());
  result.ok = torch::empty({in.planes, 1, in.h, in.w}, source.options().dtype(torch::kBool));
  float* ncc = result.ncc.data_ptr<float>();
  bool* ok = result.ok.data_ptr<bool>();
  at::parallel_for(0, in.planes * bands, 1, [&](int64_t begin, int64_t end) {
    for (int64_t task = begin; task < end; ++task) {
      const int64_t i = task / bands, row_begin = (task % bands) * kBandRows;
      const int64_t row_end = std::min(row_begin + kBandRows, in.h);
      in.Correlate(i, radius, row_begin, row_end, ncc + i * hw + row_begin * in.w, ok + i * hw + row_begin * in.w);
    }
  });
  return result;
}

// The score of SurfaceScoreByOps, one band of one batch item per task: each
// selected source's NCC rows go to a band-sized buffer and are summed at
// once, so no per-source map is written.
torch::Tensor ScoreAlongSurfaceCpu(const torch::Tensor& source, const torch::Tensor& reference,
                                   const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                                   const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface,
                                   const torch::Tensor& weights, int64_t radius, double margin) {
  const CpuPlanes in(source, reference, reference_mean, reference_var, a, b, surface, margin);
  const torch::Tensor weights_c = weights.contiguous();
  const int64_t batch = surface.size(0), hw = in.h * in.w, bands = BandCount(in.h);
  torch::Tensor score = torch::empty({batch, 1, in.h, in.w}, source.options());
  float* out = score.data_ptr<float>();
  const float* weight = weights_c.data_ptr<float>();
  at::parallel_for(0, batch * bands, 1, [&](int64_t begin, int64_t end) {
    std::vector<float> ncc(static_cast<size_t>(kBandRows * in.w)), sum(ncc.size()), weight_sum(ncc.size());
    std::unique_ptr<bool[]> ok(new bool[ncc.size()]);
    for (int64_t task = begin; task < end; ++task) {
      const int64_t item = task / bands, row_begin = (task % bands) * kBandRows;
      const int64_t row_end = std::min(row_begin + kBandRows, in.h), count = (row_end - row_begin) * in.w;
      std::fill(sum.begin(), sum.begin() + count, 0.0f);
      std::fill(weight_sum.begin(), weight_sum.begin() + count, 0.0f);
      for (int64_t s = 0; s < in.n; ++s) {
        const float* wgt = weight + (item * in.n + s) * hw + row_begin * in.w;
        bool any = false;
        for (int64_t p = 0; p < count && !any; ++p) any = wgt[p] != 0;
        if (!any) continue;  // no pixel of the band counts this source
        in.Correlate(item * in.n + s, radius, row_begin, row_end, ncc.data(), ok.get(), wgt);
        for (int64_t p = 0; p < count; ++p) {
          sum[p] += wgt[p] * (ok[p] ? ncc[p] : -1.0f);
          weight_sum[p] += wgt[p];
        }
      }
      float* out_band = out + item * hw + row_begin * in.w;
      for (int64_t p = 0; p < count; ++p) {
        out_band[p] = weight_sum[p] > 0 ? sum[p] / std::max(weight_sum[p], 1.0f) : -1.0f;
      }
    }
  });
  return score;
}

// CorrelateAlongSurfaceByOps on checked shapes.
SurfaceCorrelation CorrelateByOps(const torch::Tensor& source, const torch::Tensor& reference,
                                  const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                                  const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface,
                                  int64_t radius, double margin) {
  const int64_t n = source.size(0) / surface.size(0);
  const int64_t h = source.size(2), w = source.size(3);
  const torch::Tensor per_source = surface.repeat_interleave(n, 0);
  const torch::Tensor projected = a + per_source * b;
  const torch::Tensor z = projected.narrow(1, 2, 1);
  const torch::Tensor in_front = (z > 0) & (per_source > 0);
  const torch::Tensor inverse_z = torch::where(in_front, z.reciprocal(), torch::zeros_like(z));
  const torch::Tensor x = projected.narrow(1, 0, 1) * inverse_z;
  const torch::Tensor y = projected.narrow(1, 1, 1) * inverse_z;
  const double half_w = 0.5 * static_cast<double>(w - 1), half_h = 0.5 * static_cast<double>(h - 1);
  const torch::Tensor inside = in_front & ((x - half_w).abs() <= half_w - margin) &
                               ((y - half_h).abs() <= half_h - margin);
  const double x_scale = 2.0 / static_cast<double>(std::max<int64_t>(w - 1, 1));
  const double y_scale = 2.0 / static_cast<double>(std::max<int64_t>(h - 1, 1));
  const torch::Tensor grid = torch::stack({x.squeeze(1) * x_scale - 1.0, y.squeeze(1) * y_scale - 1.0}, -1);
  const torch::Tensor sampled = F::grid_sample(
      source, grid,
      F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kZeros).align_corners(true));
  // The three window means in one pass.
  const torch::Tensor means = WindowMean(torch::cat({sampled, sampled * sampled, reference * sampled}, 1), radius);
  const torch::Tensor s_mean = means.narrow(1, 0, 1);
  const torch::Tensor s_var = torch::clamp_min(means.narrow(1, 1, 1) - s_mean * s_mean, 0);
  const torch::Tensor covariance = means.narrow(1, 2, 1) - reference_mean * s_mean;
  SurfaceCorrelation result;
  result.ncc = covariance * torch::rsqrt(torch::clamp_min(reference_var * s_var, 1e-12));
  result.ok = inside & (s_var > 1e-10);
  return result;
}

}  // namespace

SurfaceCorrelation CorrelateAlongSurfaceByOps(const torch::Tensor& source, const torch::Tensor& reference,
                                              const torch::Tensor& reference_mean,
                                              const torch::Tensor& reference_var, const torch::Tensor& a,
                                              const torch::Tensor& b, const torch::Tensor& surface,
                                              int64_t radius, double margin) {
  CheckShapes(source, reference, reference_mean, reference_var, a, b, surface);
  return CorrelateByOps(source, reference, reference_mean, reference_var, a, b, surface, radius, margin);
}

SurfaceCorrelation CorrelateAlongSurface(const torch::Tensor& source, const torch::Tensor& reference,
                                         const torch::Tensor& reference_mean,
                                         const torch::Tensor& reference_var, const torch::Tensor& a,
                                         const torch::Tensor& b, const torch::Tensor& surface,
                                         int64_t radius, double margin) {
  CheckShapes(source, reference, reference_mean, reference_var, a, b, surface);
  if (AllCpuFloat({&source, &reference, &reference_mean, &reference_var, &a, &b, &surface})) {
    return CorrelateAlongSurfaceCpu(source, reference, reference_mean, reference_var, a, b, surface, radius,
                                    margin);
  }
  return CorrelateByOps(source, reference, reference_mean, reference_var, a, b, surface, radius, margin);
}

torch::Tensor ScoreAlongSurfaceByOps(const torch::Tensor& source, const torch::Tensor& reference,
                                    const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                                    const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface,
                                    const torch::Tensor& weights, int64_t radius, double margin) {
  CheckShapes(source, reference, reference_mean, reference_var, a, b, surface);
  CheckWeights(weights, source, surface);
  return CombineSources(
      CorrelateByOps(source, reference, reference_mean, reference_var, a, b, surface, radius, margin), weights);
}

torch::Tensor ScoreAlongSurface(const torch::Tensor& source, const torch::Tensor& reference,
                                const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                                const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface,
                                const torch::Tensor& weights, int64_t radius, double margin) {
  CheckShapes(source, reference, reference_mean, reference_var, a, b, surface);
  CheckWeights(weights, source, surface);
  if (AllCpuFloat({&source, &reference, &reference_mean, &reference_var, &a, &b, &surface, &weights})) {
    return ScoreAlongSurfaceCpu(source, reference, reference_mean, reference_var, a, b, surface, weights, radius,
                                margin);
  }
  return CombineSources(
      CorrelateByOps(source, reference, reference_mean, reference_var, a, b, surface, radius, margin), weights);
}

torch::Tensor CombineSources(const SurfaceCorrelation& correlation, const torch::Tensor& weights) {
  const int64_t batch = weights.size(0), n = weights.size(1), h = weights.size(2), w = weights.size(3);
  const torch::Tensor ncc = correlation.ncc.view({batch, n, h, w}), ok = correlation.ok.view({batch, n, h, w});
  const torch::Tensor per_source = torch::where(ok, ncc, torch::full_like(ncc, -1.0));
  const torch::Tensor weight_sum = weights.sum(1, /*keepdim=*/true);
  return torch::where(weight_sum > 0, (per_source * weights).sum(1, true) / weight_sum.clamp_min(1),
                      torch::full_like(weight_sum, -1.0));
}

}  // namespace dispmvs::model
