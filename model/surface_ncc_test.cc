#include "model/surface_ncc.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include <torch/torch.h>

#include "model/geometry.h"
#include "model/surface_ncc_rows.h"

namespace dispmvs::model {
namespace {

struct Inputs {
  torch::Tensor source, reference, reference_mean, reference_var, a, b, surface;
};

// Two batch items with three sources each, real epipolar pairs (one source
// behind part of the scene's rays, one looking away to the side) and a
// surface with invalid, negative and far values: every branch of the
// sampling is taken.
Inputs MakeInputs(int64_t radius, int64_t h = 37, int64_t w = 53) {
  torch::manual_seed(3);
  const int64_t b = 2, n = 3;
  Inputs in;
  in.source = torch::rand({b * n, 1, h, w});
  const torch::Tensor reference = torch::rand({b, 1, h, w});
  in.reference = reference.repeat_interleave(n, 0);
  const auto mean = [&](const torch::Tensor& x) {
    return torch::nn::functional::avg_pool2d(
        x, torch::nn::functional::AvgPool2dFuncOptions(2 * radius + 1).stride(1).padding(radius).count_include_pad(false));
  };
  in.reference_mean = mean(in.reference);
  in.reference_var = torch::clamp_min(mean(in.reference * in.reference) - in.reference_mean.square(), 0);
  const torch::Tensor K = torch::tensor({40.0f, 0.0f, 26.0f, 0.0f, 42.0f, 18.0f, 0.0f, 0.0f, 1.0f}).view({1, 3, 3});
  std::vector<torch::Tensor> rotations, translations;
  for (int64_t i = 0; i < b * n; ++i) {
    const double angle = 0.05 * static_cast<double>(i) - 0.1;
    rotations.push_back(torch::tensor({std::cos(angle), 0.0, std::sin(angle), 0.0, 1.0, 0.0, -std::sin(angle), 0.0,
                                       std::cos(angle)},
                                      torch::kFloat32)
                            .view({3, 3}));
    translations.push_back(torch::tensor({0.4 - 0.2 * static_cast<double>(i), 0.1, i == 2 ? 3.0 : -0.05},
                                         torch::kFloat32));
  }
  const EpipolarPair pair = MakeEpipolarPair(K.expand({b * n, 3, 3}), K.expand({b * n, 3, 3}),
                                             torch::stack(rotations), torch::stack(translations), h, w);
  in.a = pair.a;
  in.b = pair.b;
  in.surface = 0.1 + torch::rand({b, 1, h, w}) * 0.6;
  in.surface.index_put_({0, 0, torch::indexing::Slice(0, std::min<int64_t>(5, h / 2))}, 0.0);
  in.surface.index_put_({1, 0, torch::indexing::Slice(h / 4, h / 4 + 2)}, -0.3);
  in.surface.index_put_({1, 0, torch::indexing::Slice(h / 2, h / 2 + 2)}, 5.0);
  return in;
}

TEST(SurfaceNccTest, CpuPassEqualsTheOperations) {
  for (const int64_t radius : {1, 3}) {
    for (const bool per_pixel_b : {false, true}) {
      Inputs in = MakeInputs(radius);
      if (per_pixel_b) in.b = in.b.expand_as(in.a).contiguous() * 1.01;
      const SurfaceCorrelation fast = CorrelateAlongSurface(in.source, in.reference, in.reference_mean,
                                                            in.reference_var, in.a, in.b, in.surface, radius, radius);
      const SurfaceCorrelation ops = CorrelateAlongSurfaceByOps(
          in.source, in.reference, in.reference_mean, in.reference_var, in.a, in.b, in.surface, radius, radius);
      ASSERT_EQ(fast.ncc.sizes(), ops.ncc.sizes());
      // Matches exactly on the border between counting and not may flip
      // with the last bit of the division: allow a handful.
      const int64_t differing = (fast.ok != ops.ok).sum().item<int64_t>();
      EXPECT_LE(differing, 3) << "radius " << radius;
      const int64_t counted = ops.ok.sum().item<int64_t>();
      EXPECT_GT(counted, fast.ok.numel() / 4);  // the check sees real matches
      EXPECT_LT(counted, fast.ok.numel());      // and ones that do not count
      const torch::Tensor both = fast.ok & ops.ok;
      EXPECT_LT((fast.ncc - ops.ncc).abs().masked_select(both).max().item<float>(), 2e-4)
          << "radius " << radius << " per-pixel b " << per_pixel_b;
    }
  }
}

// Images smaller than the window: every window is clipped on both sides.
TEST(SurfaceNccTest, CpuPassEqualsTheOperationsOnImagesSmallerThanTheWindow) {
  const Inputs in = MakeInputs(/*radius=*/4, /*h=*/5, /*w=*/7);
  const SurfaceCorrelation fast = CorrelateAlongSurface(in.source, in.reference, in.reference_mean,
                                                        in.reference_var, in.a, in.b, in.surface, 4, 0);
  const SurfaceCorrelation ops = CorrelateAlongSurfaceByOps(in.source, in.reference, in.reference_mean,
                                                            in.reference_var, in.a, in.b, in.surface, 4, 0);
  EXPECT_LE((fast.ok != ops.ok).sum().item<int64_t>(), 1);
  EXPECT_GT(ops.ok.sum().item<int64_t>(), 0);
  const torch::Tensor both = fast.ok & ops.ok;
  EXPECT_LT((fast.ncc - ops.ncc).abs().masked_select(both).max().item<float>(), 2e-4);
}

// Taller images run as bands of 64 rows, each with its own sums: the same
// as the operations over the band borders, and the same bits whatever the
// number of threads.
TEST(SurfaceNccTest, BandsEqualTheOperationsAndDoNotDependOnThreads) {
  const Inputs in = MakeInputs(/*radius=*/3, /*h=*/150, /*w=*/41);
  const int threads = at::get_num_threads();
  torch::set_num_threads(1);
  const SurfaceCorrelation one = CorrelateAlongSurface(in.source, in.reference, in.reference_mean,
                                                       in.reference_var, in.a, in.b, in.surface, 3, 3);
  torch::set_num_threads(2);
  const SurfaceCorrelation two = CorrelateAlongSurface(in.source, in.reference, in.reference_mean,
                                                       in.reference_var, in.a, in.b, in.surface, 3, 3);
  torch::set_num_threads(threads);
  EXPECT_TRUE(torch::equal(one.ncc, two.ncc));
  EXPECT_TRUE(torch::equal(one.ok, two.ok));
  const SurfaceCorrelation ops = CorrelateAlongSurfaceByOps(in.source, in.reference, in.reference_mean,
                                                            in.reference_var, in.a, in.b, in.surface, 3, 3);
  EXPECT_LE((one.ok != ops.ok).sum().item<int64_t>(), 3);
  const torch::Tensor both = one.ok & ops.ok;
  EXPECT_GT(both.narrow(2, 60, 10).sum().item<int64_t>(), 0);  // rows about the first band border count
  EXPECT_LT((one.ncc - ops.ncc).abs().masked_select(both).max().item<float>(), 2e-4);
}

// The two builds of the row pass (surface_ncc_rows.h) on the same planes:
// every source of MakeInputs (behind the camera, off to the side, invalid
// and far surface values), a constant and a per-pixel b, a width that is
// not a multiple of the AVX2 build's eight lanes, with and without a
// `needed` mask. The same flags but for matches exactly on the border, the
// same NCC to float rounding, and 0 / false where not needed.
TEST(SurfaceNccTest, PortableAndAvx2RowPassesAgree) {
  if (!CpuHasAvx2Fma()) GTEST_SKIP() << "this processor has no AVX2 and FMA";
  const int64_t radius = 3, h = 150, w = 53;
  for (const bool per_pixel_b : {false, true}) {
    Inputs in = MakeInputs(radius, h, w);
    if (per_pixel_b) in.b = in.b.expand_as(in.a).contiguous() * 1.01;
    const int64_t planes = in.source.size(0), n = planes / in.surface.size(0), hw = h * w;
    torch::manual_seed(7);
    const torch::Tensor needed = (torch::rand({h, w}) > 0.3).to(torch::kFloat32);
    int64_t counted = 0;
    for (int64_t i = 0; i < planes; ++i) {
      const float half_w = 0.5f * static_cast<float>(w - 1), half_h = 0.5f * static_cast<float>(h - 1);
      const PlaneSampler sampler{in.source.data_ptr<float>() + i * hw,
                                 in.a.data_ptr<float>() + i * 3 * hw,
                                 in.b.data_ptr<float>() + i * (per_pixel_b ? 3 * hw : 3),
                                 in.surface.data_ptr<float>() + (i / n) * hw,
                                 h,
                                 w,
                                 per_pixel_b,
                                 half_w,
                                 half_h,
                                 half_w - static_cast<float>(radius),
                                 half_h - static_cast<float>(radius)};
      for (const bool masked : {false, true}) {
        const float* mask = masked ? needed.data_ptr<float>() : nullptr;
        std::vector<float> ncc_portable(static_cast<size_t>(hw)), ncc_avx2(static_cast<size_t>(hw));
        std::unique_ptr<bool[]> ok_portable(new bool[hw]), ok_avx2(new bool[hw]);
        const float* ref = in.reference.data_ptr<float>() + i * hw;
        const float* mean = in.reference_mean.data_ptr<float>() + i * hw;
        const float* var = in.reference_var.data_ptr<float>() + i * hw;
        CorrelateRowsPortable(sampler, ref, mean, var, radius, 0, h, ncc_portable.data(), ok_portable.get(), mask);
        CorrelateRowsAvx2(sampler, ref, mean, var, radius, 0, h, ncc_avx2.data(), ok_avx2.get(), mask);
        int64_t flipped = 0;
        float largest = 0;
        for (int64_t p = 0; p < hw; ++p) {
          flipped += ok_portable[p] != ok_avx2[p];
          if (ok_portable[p] && ok_avx2[p]) {
            largest = std::max(largest, std::abs(ncc_portable[p] - ncc_avx2[p]));
            ++counted;
          }
          if (masked && needed.data_ptr<float>()[p] == 0) {
            EXPECT_FALSE(ok_avx2[p]);
            EXPECT_EQ(ncc_avx2[p], 0.0f);
          }
        }
        EXPECT_LE(flipped, 3) << "plane " << i << " per-pixel b " << per_pixel_b << " masked " << masked;
        EXPECT_LT(largest, 2e-5) << "plane " << i << " per-pixel b " << per_pixel_b << " masked " << masked;
      }
    }
    EXPECT_GT(counted, planes * hw / 4);  // the comparison sees real matches
  }
}

// A plane of one row: the AVX2 build would read a second row for pixels
// without a 2x2 block, so CorrelateRows gives such planes to the portable
// build (the same bits).
TEST(SurfaceNccTest, OneRowPlanesTakeThePortablePass) {
  EXPECT_FALSE(Avx2RowsFit(1, 40));
  EXPECT_TRUE(Avx2RowsFit(2, 40));
  const int64_t radius = 1, h = 1, w = 40;
  Inputs in = MakeInputs(radius, /*h=*/2, w);  // two rows, of which the first is the plane
  const torch::Tensor source = in.source.select(0, 0).select(0, 0).narrow(0, 0, 1).contiguous();
  const torch::Tensor reference = in.reference.select(0, 0).select(0, 0).narrow(0, 0, 1).contiguous();
  const torch::Tensor a = in.a.select(0, 0).narrow(1, 0, 1).contiguous();  // [3,1,W]
  const torch::Tensor b = in.b.select(0, 0).reshape({3}).contiguous();
  const torch::Tensor surface = in.surface.select(0, 0).select(0, 0).narrow(0, 0, 1).clamp_min(0.2).contiguous();
  const torch::Tensor mean = torch::full({h, w}, 0.5f), var = torch::full({h, w}, 0.08f);
  // The match counts anywhere in the source's row span (limit_y generous:
  // the one-row source is only there to be read).
  const PlaneSampler sampler{source.data_ptr<float>(), a.data_ptr<float>(), b.data_ptr<float>(),
                             surface.data_ptr<float>(), h, w, false, 0.5f * (w - 1), 0.0f, 0.5f * (w - 1), 100.0f};
  std::vector<float> ncc_dispatched(w), ncc_portable(w);
  std::unique_ptr<bool[]> ok_dispatched(new bool[w]), ok_portable(new bool[w]);
  CorrelateRows(sampler, reference.data_ptr<float>(), mean.data_ptr<float>(), var.data_ptr<float>(), radius, 0, h,
                ncc_dispatched.data(), ok_dispatched.get(), nullptr);
  CorrelateRowsPortable(sampler, reference.data_ptr<float>(), mean.data_ptr<float>(), var.data_ptr<float>(), radius,
                        0, h, ncc_portable.data(), ok_portable.get(), nullptr);
  int64_t counted = 0;
  for (int64_t j = 0; j < w; ++j) {
    EXPECT_EQ(ok_dispatched[j], ok_portable[j]) << j;
    if (ok_portable[j]) {
      EXPECT_EQ(ncc_dispatched[j], ncc_portable[j]) << j;
      ++counted;
    }
  }
  EXPECT_GT(counted, 0);
}

// The score of a surface without per-source maps: the weighted mean of the
// selected sources' NCC (-1 for one that does not count), -1 where none is
// selected, as the operations give it; a source no pixel of a band selects
// is skipped there without changing anything.
TEST(SurfaceNccTest, ScoreEqualsTheCombinedCorrelations) {
  const Inputs in = MakeInputs(/*radius=*/3, /*h=*/150, /*w=*/41);
  const int64_t b = 2, n = 3, h = 150, w = 41;
  torch::manual_seed(5);
  torch::Tensor weights = (torch::rand({b, n, h, w}) > 0.4).to(torch::kFloat32);
  weights.index_put_({0, 1, torch::indexing::Slice(64, 128)}, 0.0);  // source 1 unselected in a whole band
  weights.index_put_({1, torch::indexing::Slice(), torch::indexing::Slice(10, 12)}, 0.0);  // no source at all
  const torch::Tensor fast = ScoreAlongSurface(in.source, in.reference, in.reference_mean, in.reference_var, in.a,
                                               in.b, in.surface, weights, 3, 3);
  ASSERT_EQ(fast.sizes(), torch::IntArrayRef({b, 1, h, w}));
  const torch::Tensor from_cpu = CombineSources(
      CorrelateAlongSurface(in.source, in.reference, in.reference_mean, in.reference_var, in.a, in.b, in.surface, 3, 3),
      weights);
  EXPECT_LT((fast - from_cpu).abs().max().item<float>(), 1e-6);
  const torch::Tensor ops = ScoreAlongSurfaceByOps(in.source, in.reference, in.reference_mean, in.reference_var,
                                                   in.a, in.b, in.surface, weights, 3, 3);
  // Where an ok flag flips with the last bit, one source's term moves to -1.
  EXPECT_LE(((fast - ops).abs() > 2e-4).sum().item<int64_t>(), 3);
  EXPECT_TRUE(torch::equal(fast.narrow(0, 1, 1).narrow(2, 10, 2), torch::full({1, 1, 2, w}, -1.0f)));
  // By hand at one pixel with two sources selected.
  const int64_t i = 100, j = 20;
  const SurfaceCorrelation c = CorrelateAlongSurface(in.source, in.reference, in.reference_mean, in.reference_var,
                                                     in.a, in.b, in.surface, 3, 3);
  double sum = 0, count = 0;
  for (int64_t s = 0; s < n; ++s) {
    if (weights[1][s][i][j].item<float>() == 0) continue;
    sum += c.ok[n + s][0][i][j].item<bool>() ? c.ncc[n + s][0][i][j].item<float>() : -1.0;
    count += 1;
  }
  ASSERT_GT(count, 0);
  EXPECT_NEAR(fast[1][0][i][j].item<float>(), sum / count, 1e-6);
  EXPECT_THROW(ScoreAlongSurface(in.source, in.reference, in.reference_mean, in.reference_var, in.a, in.b,
                                 in.surface, weights.narrow(1, 0, 2), 3, 3),
               std::invalid_argument);
}

// The reference's tensors once per batch item ([B,1,H,W], read by every
// source of the item) give exactly what copies per source give, on both
// paths: the refinement passes them so, N times less memory.
TEST(SurfaceNccTest, AReferenceSharedByItsSourcesEqualsOneCopyPerSource) {
  const int64_t radius = 2, n = 3;
  const Inputs in = MakeInputs(radius);
  const auto shared = [&](const torch::Tensor& per_source) {
    return per_source.view({2, n, 1, per_source.size(2), per_source.size(3)}).select(1, 0);
  };
  ASSERT_TRUE(torch::equal(shared(in.reference).repeat_interleave(n, 0), in.reference));
  torch::manual_seed(9);
  const torch::Tensor weights = (torch::rand({2, n, in.source.size(2), in.source.size(3)}) > 0.3).to(torch::kFloat32);
  const auto correlate = [&](bool by_ops, const torch::Tensor& ref, const torch::Tensor& mean, const torch::Tensor& var) {
    return by_ops ? CorrelateAlongSurfaceByOps(in.source, ref, mean, var, in.a, in.b, in.surface, radius, radius)
                  : CorrelateAlongSurface(in.source, ref, mean, var, in.a, in.b, in.surface, radius, radius);
  };
  for (const bool by_ops : {false, true}) {
    const SurfaceCorrelation copies = correlate(by_ops, in.reference, in.reference_mean, in.reference_var);
    const SurfaceCorrelation once =
        correlate(by_ops, shared(in.reference), shared(in.reference_mean), shared(in.reference_var));
    EXPECT_TRUE(torch::equal(copies.ncc, once.ncc)) << "by ops " << by_ops;
    EXPECT_TRUE(torch::equal(copies.ok, once.ok)) << "by ops " << by_ops;
  }
  const torch::Tensor score = ScoreAlongSurface(in.source, in.reference, in.reference_mean, in.reference_var, in.a,
                                                in.b, in.surface, weights, radius, radius);
  const torch::Tensor score_once =
      ScoreAlongSurface(in.source, shared(in.reference), shared(in.reference_mean), shared(in.reference_var), in.a,
                        in.b, in.surface, weights, radius, radius);
  EXPECT_TRUE(torch::equal(score, score_once));
}

TEST(SurfaceNccTest, RefusesMismatchedShapes) {
  const Inputs in = MakeInputs(2);
  EXPECT_THROW(CorrelateAlongSurface(in.source, in.reference, in.reference_mean, in.reference_var, in.a, in.b,
                                     in.surface.narrow(3, 0, 5), 2, 2),
               std::invalid_argument);
  EXPECT_THROW(CorrelateAlongSurface(in.source, in.reference.narrow(0, 0, 4), in.reference_mean.narrow(0, 0, 4),
                                     in.reference_var.narrow(0, 0, 4), in.a, in.b, in.surface, 2, 2),
               std::invalid_argument);
  // One per batch item, or one per source, but all three alike.
  EXPECT_THROW(CorrelateAlongSurface(in.source, in.reference.narrow(0, 0, 2), in.reference_mean, in.reference_var,
                                     in.a, in.b, in.surface, 2, 2),
               std::invalid_argument);
  EXPECT_THROW(CorrelateAlongSurface(in.source, in.reference, in.reference_mean, in.reference_var, in.a,
                                     in.b.narrow(1, 0, 2), in.surface, 2, 2),
               std::invalid_argument);
  // A batch of surfaces that does not divide the sources.
  EXPECT_THROW(CorrelateAlongSurface(in.source.narrow(0, 0, 5), in.reference.narrow(0, 0, 5),
                                     in.reference_mean.narrow(0, 0, 5), in.reference_var.narrow(0, 0, 5),
                                     in.a.narrow(0, 0, 5), in.b.narrow(0, 0, 5), in.surface, 2, 2),
               std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
