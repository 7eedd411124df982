#include "model/surface_ncc.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/surface_ncc_rows.h"
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
  const std::vector<int64_t> shared = {surface.defined() ? surface.size(0) : -1, 1, source.size(2),
                                       source.size(3)};
  for (const torch::Tensor* t : {&reference, &reference_mean, &reference_var}) {
    if (!t->defined() || (t->sizes() != planes && t->sizes() != torch::IntArrayRef(shared)) ||
        t->sizes() != reference.sizes()) {
      fail("the reference tensors must be [B,1,H,W] (surface's batch) or source's shape, all three alike");
    }
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
  bool ref_per_plane;  // the reference tensors [B*N,...], else one per batch item [B,...]
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
        ref_per_plane(reference.size(0) == source.size(0)),
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
    const int64_t hw = h * w, offset = (ref_per_plane ? i : i / n) * hw;
    CorrelateRows(Sampler(i), ref.data_ptr<float>() + offset, mean.data_ptr<float>() + offset,
                  var.data_ptr<float>() + offset, radius, row_begin, row_end, ncc, ok, needed);
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

// One source's share of the band's score: sum += weight * (ncc where ok,
// else -1), weight_sum += weight. Branch-free over unaliased pointers, and
// ok read as bytes (GCC has no vector type for bool), so that the compiler
// vectorises it: the conditional form on bool stayed scalar and took a
// tenth of the refinement's time at full resolution.
void AccumulateSource(const float* __restrict weight, const float* __restrict ncc, const uint8_t* __restrict ok,
                      int64_t count, float* __restrict sum, float* __restrict weight_sum) {
  for (int64_t p = 0; p < count; ++p) {
    // ok ? ncc : -1 as arithmetic on ok's 0 or 1.
    const float counts = static_cast<float>(static_cast<int32_t>(ok[p]));
    sum[p] += weight[p] * (counts * ncc[p] + (counts - 1.0f));
    weight_sum[p] += weight[p];
  }
}

// The band's score: the mean over the selected sources, -1 where none is.
// (Vectorised where the file is built with -fno-trapping-math, as
// model/CMakeLists.txt builds it.)
void MeanOverSources(const float* __restrict sum, const float* __restrict weight_sum, int64_t count,
                     float* __restrict out) {
  for (int64_t p = 0; p < count; ++p) {
    const float mean = sum[p] / std::max(weight_sum[p], 1.0f);
    out[p] = weight_sum[p] > 0 ? mean : -1.0f;
  }
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
        AccumulateSource(wgt, ncc.data(), reinterpret_cast<const uint8_t*>(ok.get()), count, sum.data(), weight_sum.data());
      }
      MeanOverSources(sum.data(), weight_sum.data(), count, out + item * hw + row_begin * in.w);
    }
  });
  return score;
}

// CorrelateAlongSurfaceByOps on checked shapes.
SurfaceCorrelation CorrelateByOps(const torch::Tensor& source, const torch::Tensor& reference_in,
                                  const torch::Tensor& reference_mean_in, const torch::Tensor& reference_var_in,
                                  const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface,
                                  int64_t radius, double margin) {
  const int64_t n = source.size(0) / surface.size(0);
  const auto per_plane = [&](const torch::Tensor& t) {
    return t.size(0) == source.size(0) ? t : t.repeat_interleave(n, 0);
  };
  const torch::Tensor reference = per_plane(reference_in), reference_mean = per_plane(reference_mean_in),
                      reference_var = per_plane(reference_var_in);
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
