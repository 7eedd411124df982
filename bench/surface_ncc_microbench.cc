// Microbenchmark (Google Benchmark) of the photometric refinement's inner
// pass (model/surface_ncc_rows.h): one source plane's NCC along a surface,
// in the bands of 64 rows the refinement runs, by the portable build and by
// the AVX2 build, one thread. Every hypothesis of the refinement's search
// and every propagated candidate is one such pass per source, and then one
// BestOfShiftedWindows over its score (model/shifted_windows.h), timed here
// too at the threads LibTorch uses.
//
//   surface_ncc_microbench [--benchmark_repetitions=5]
//
// Arguments: width, height. The geometry is a real epipolar pair (a source
// 0.3 units to the side, turned by 2 degrees) and a slanted, wavy surface,
// so that matches land at fractional positions across the image and some
// leave it; the images are random (the cost does not depend on them).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include "model/shifted_windows.h"
#include "model/surface_ncc_rows.h"

namespace {

using dispmvs::model::PlaneSampler;

struct Plane {
  int64_t h, w;
  std::vector<float> source, reference, mean, var, a, b, surface, ncc;
  std::unique_ptr<bool[]> ok;

  Plane(int64_t width, int64_t height) : h(height), w(width) {
    const int64_t hw = h * w;
    std::mt19937 random(1);
    std::uniform_real_distribution<float> uniform(0, 1);
    source.resize(hw);
    reference.resize(hw);
    for (float& v : source) v = uniform(random);
    for (float& v : reference) v = uniform(random);
    mean.assign(hw, 0.5f);
    var.assign(hw, 1.0f / 12.0f);
    // a = K R K^-1 (x, y, 1), b = K T with K = (f, f, w/2, h/2).
    const double f = 0.9 * static_cast<double>(w), angle = 2.0 * M_PI / 180.0;
    const double c = std::cos(angle), s = std::sin(angle), cx = 0.5 * w, cy = 0.5 * h;
    a.resize(3 * hw);
    surface.resize(hw);
    for (int64_t y = 0; y < h; ++y) {
      for (int64_t x = 0; x < w; ++x) {
        const int64_t p = y * w + x;
        const double rx = (x - cx) / f, ry = (y - cy) / f;
        const double qx = c * rx + s, qy = ry, qz = -s * rx + c;
        a[p] = static_cast<float>(f * qx + cx * qz);
        a[hw + p] = static_cast<float>(f * qy + cy * qz);
        a[2 * hw + p] = static_cast<float>(qz);
        surface[p] = static_cast<float>(0.25 + 0.1 * y / h + 0.02 * std::sin(0.05 * x));
      }
    }
    b = {static_cast<float>(f * -0.3), 0.0f, 0.0f};
    ncc.resize(hw);
    ok.reset(new bool[hw]);
  }

  PlaneSampler Sampler() const {
    const float half_w = 0.5f * static_cast<float>(w - 1), half_h = 0.5f * static_cast<float>(h - 1);
    return PlaneSampler{source.data(), a.data(), b.data(), surface.data(), h, w, false,
                        half_w, half_h, half_w - 3, half_h - 3};
  }
};

template <bool kAvx2>
void BM_SurfaceNccPlane(benchmark::State& state) {
  if (kAvx2 && !dispmvs::model::CpuHasAvx2Fma()) {
    state.SkipWithError("no AVX2 and FMA on this processor");
    return;
  }
  Plane plane(state.range(0), state.range(1));
  const PlaneSampler sampler = plane.Sampler();
  constexpr int64_t kBand = 64, kRadius = 3;
  for (auto _ : state) {
    for (int64_t begin = 0; begin < plane.h; begin += kBand) {
      const int64_t end = std::min(begin + kBand, plane.h);
      float* ncc = plane.ncc.data() + begin * plane.w;
      bool* ok = plane.ok.get() + begin * plane.w;
      if (kAvx2) {
        dispmvs::model::CorrelateRowsAvx2(sampler, plane.reference.data(), plane.mean.data(), plane.var.data(),
                                          kRadius, begin, end, ncc, ok, nullptr);
      } else {
        dispmvs::model::CorrelateRowsPortable(sampler, plane.reference.data(), plane.mean.data(),
                                              plane.var.data(), kRadius, begin, end, ncc, ok, nullptr);
      }
    }
    benchmark::DoNotOptimize(plane.ncc.data());
  }
  state.SetItemsProcessed(state.iterations() * plane.h * plane.w);
}

BENCHMARK_TEMPLATE(BM_SurfaceNccPlane, false)->Args({640, 480})->Args({320, 240})->Unit(benchmark::kMillisecond);
BENCHMARK_TEMPLATE(BM_SurfaceNccPlane, true)->Args({640, 480})->Args({320, 240})->Unit(benchmark::kMillisecond);

// The refinement's shifted windows (window_shift 2) over one score map.
void BM_BestOfShiftedWindows(benchmark::State& state) {
  torch::manual_seed(1);
  const torch::Tensor score = torch::rand({1, 1, state.range(1), state.range(0)});
  for (auto _ : state) benchmark::DoNotOptimize(dispmvs::model::BestOfShiftedWindows(score, 2));
  state.SetItemsProcessed(state.iterations() * state.range(0) * state.range(1));
}

BENCHMARK(BM_BestOfShiftedWindows)->Args({640, 480})->Args({320, 240})->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
