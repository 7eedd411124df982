#include "model/correlation.h"

#include <cmath>
#include <optional>
#include <string>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "model/correlation_cpu.h"

namespace dispmvs::model {
namespace {

// A plain [C][H][W] image of one batch entry, for the naive reference.
struct Map {
  int64_t c = 0, h = 0, w = 0;
  std::vector<double> v;
  double at(int64_t ch, int64_t y, int64_t x) const { return v[(ch * h + y) * w + x]; }
};

Map ToMap(const torch::Tensor& t, int64_t b) {
  Map m;
  m.c = t.size(1);
  m.h = t.size(2);
  m.w = t.size(3);
  auto a = t.accessor<float, 4>();
  for (int64_t c = 0; c < m.c; ++c)
    for (int64_t y = 0; y < m.h; ++y)
      for (int64_t x = 0; x < m.w; ++x) m.v.push_back(a[b][c][y][x]);
  return m;
}

// 2x2 average pooling; a block cut by the border averages the pixels it has.
Map Pool(const Map& in) {
  Map out;
  out.c = in.c;
  out.h = (in.h + 1) / 2;
  out.w = (in.w + 1) / 2;
  for (int64_t c = 0; c < out.c; ++c)
    for (int64_t y = 0; y < out.h; ++y)
      for (int64_t x = 0; x < out.w; ++x) {
        double sum = 0;
        int count = 0;
        for (int64_t dy = 0; dy < 2; ++dy)
          for (int64_t dx = 0; dx < 2; ++dx)
            if (2 * y + dy < in.h && 2 * x + dx < in.w) {
              sum += in.at(c, 2 * y + dy, 2 * x + dx);
              ++count;
            }
        out.v.push_back(sum / count);
      }
  return out;
}

// Bilinear interpolation at pixel-index position (x, y); pixels outside the
// map read 0.
double Bilinear(const Map& m, int64_t c, double x, double y) {
  const double x0 = std::floor(x), y0 = std::floor(y);
  double sum = 0;
  for (int dy = 0; dy < 2; ++dy)
    for (int dx = 0; dx < 2; ++dx) {
      const int64_t xi = static_cast<int64_t>(x0) + dx;
      const int64_t yi = static_cast<int64_t>(y0) + dy;
      if (xi < 0 || yi < 0 || xi >= m.w || yi >= m.h) continue;
      const double wx = dx ? x - x0 : 1 - (x - x0);
      const double wy = dy ? y - y0 : 1 - (y - y0);
      sum += wx * wy * m.at(c, yi, xi);
    }
  return sum;
}

// The three paths of Lookup: the ATen ops (autograd on), the fused CPU pass
// of correlation_cpu.h in inference (autograd off) and in training (autograd
// on, features requiring a gradient: the pass as an autograd node). C = 19
// exercises the fused pass's vector lanes and its tail.
enum class Path { kAtenOps, kFusedInference, kFusedTraining };

class EpipolarCorrelationPathTest : public ::testing::TestWithParam<Path> {
 protected:
  void SetUp() override {
    if (GetParam() == Path::kFusedInference) no_grad_.emplace();
  }
  CorrelationImpl impl() const {
    return GetParam() == Path::kAtenOps ? CorrelationImpl::kAtenOps : CorrelationImpl::kAuto;
  }
  // A feature map as the path needs it: a leaf requiring a gradient when
  // training.
  torch::Tensor Features(torch::Tensor t) const {
    return GetParam() == Path::kFusedTraining ? t.requires_grad_(true) : t;
  }

 private:
  std::optional<torch::NoGradGuard> no_grad_;
};

TEST_P(EpipolarCorrelationPathTest, MatchesNaivePerPixelLoop) {
  torch::manual_seed(7);
  const int64_t B = 2, C = 19, H = 7, W = 6, h = 4, w = 5, levels = 3, samples = 5;
  const torch::Tensor source = Features(torch::randn({B, C, H, W}));
  const torch::Tensor ref = Features(torch::randn({B, C, h, w}));
  const torch::Tensor base = torch::rand({B, 2, h, w}) * 10.0 - 2.0;  // some outside
  const torch::Tensor angle = torch::rand({B, 1, h, w}) * 6.283;
  torch::Tensor dir = torch::cat({torch::cos(angle), torch::sin(angle)}, 1);
  dir.index_put_({0, torch::indexing::Slice(), 1, 1}, 0.0);  // a degenerate pixel
  const torch::Tensor eflow = torch::rand({B, 1, h, w}) * 4.0 - 2.0;

  const EpipolarCorrelation corr(source, levels, samples, impl());
  ASSERT_EQ(corr.levels(), levels);
  ASSERT_EQ(corr.channels(), levels * samples);
  const CorrelationSamples out = corr.Lookup(ref, base, dir, eflow);
  ASSERT_EQ(out.cost.sizes(), torch::IntArrayRef({B, levels * samples, h, w}));
  ASSERT_EQ(out.inside.sizes(), out.cost.sizes());

  const torch::Tensor cost_values = out.cost.detach();
  auto cost = cost_values.accessor<float, 4>();
  auto inside = out.inside.accessor<bool, 4>();
  auto bxy = base.accessor<float, 4>();
  auto d = dir.accessor<float, 4>();
  auto e = eflow.accessor<float, 4>();
  int outside_count = 0;
  for (int64_t b = 0; b < B; ++b) {
    std::vector<Map> pyramid{ToMap(source.detach(), b)};
    for (int64_t l = 1; l < levels; ++l) pyramid.push_back(Pool(pyramid.back()));
    const Map r = ToMap(ref.detach(), b);
    for (int64_t y = 0; y < h; ++y)
      for (int64_t x = 0; x < w; ++x) {
        const double mx = bxy[b][0][y][x] + d[b][0][y][x] * e[b][0][y][x];
        const double my = bxy[b][1][y][x] + d[b][1][y][x] * e[b][0][y][x];
        for (int64_t l = 0; l < levels; ++l) {
          const double s = std::pow(2.0, static_cast<double>(l));
          for (int64_t k = 0; k < samples; ++k) {
            const double o = static_cast<double>(k) - (samples - 1) / 2.0;
            const double px = (mx + 0.5) / s - 0.5 + o * d[b][0][y][x];
            const double py = (my + 0.5) / s - 0.5 + o * d[b][1][y][x];
            double dot = 0;
            for (int64_t c = 0; c < C; ++c) dot += r.at(c, y, x) * Bilinear(pyramid[l], c, px, py);
            const int64_t ch = l * samples + k;
            EXPECT_NEAR(cost[b][ch][y][x], dot / C, 1e-5) << b << " " << ch << " " << y << " " << x;
            const bool in = px >= 0 && py >= 0 && px <= pyramid[l].w - 1 && py <= pyramid[l].h - 1;
            EXPECT_EQ(inside[b][ch][y][x], in);
            outside_count += in ? 0 : 1;
          }
        }
      }
  }
  EXPECT_GT(outside_count, 0);  // the test did exercise the border
}

// A ramp f(x, y) = x makes the cost the x coordinate (in stage pixels) of the
// sample: checks the centre, the one-pixel spacing and its 2^level growth.
TEST(EpipolarCorrelationTest, SampleSpacingIsOnePixelOfEachLevel) {
  const int64_t W = 16, H = 4;
  const torch::Tensor ramp =
      torch::arange(W, torch::kFloat).view({1, 1, 1, W}).expand({1, 1, H, W}).contiguous();
  const EpipolarCorrelation corr(ramp, /*levels=*/2, /*samples=*/3);
  const torch::Tensor ref = torch::ones({1, 1, 1, 1});
  const torch::Tensor base = torch::tensor({3.0f, 1.0f}).view({1, 2, 1, 1});
  const torch::Tensor dir = torch::tensor({1.0f, 0.0f}).view({1, 2, 1, 1});
  const torch::Tensor eflow = torch::full({1, 1, 1, 1}, 4.5f);  // match at x = 7.5
  const torch::Tensor cost = corr.Lookup(ref, base, dir, eflow).cost.flatten();
  // Level 0: 7.5 + {-1, 0, 1}. Level 1 (pooled ramp: 2j + 0.5): 7.5 + {-2, 0, 2}.
  const std::vector<float> expected{6.5f, 7.5f, 8.5f, 5.5f, 7.5f, 9.5f};
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_NEAR(cost[static_cast<int64_t>(i)].item<float>(), expected[i], 1e-5) << i;
  }
}

TEST_P(EpipolarCorrelationPathTest, OutsideSamplesReadZeroAndAreReported) {
  const torch::Tensor ones = Features(torch::ones({1, 2, 4, 4}));
  const EpipolarCorrelation corr(ones, 1, 3, impl());
  const torch::Tensor ref = Features(torch::ones({1, 2, 1, 1}));
  const torch::Tensor dir = torch::tensor({1.0f, 0.0f}).view({1, 2, 1, 1});
  const torch::Tensor eflow = torch::zeros({1, 1, 1, 1});
  // Samples at x = -1.5, -0.5, 0.5 on row 2: outside, half outside, inside.
  const torch::Tensor base = torch::tensor({-0.5f, 2.0f}).view({1, 2, 1, 1});
  const CorrelationSamples out = corr.Lookup(ref, base, dir, eflow);
  EXPECT_NEAR(out.cost[0][0][0][0].item<float>(), 0.0f, 1e-6);
  EXPECT_NEAR(out.cost[0][1][0][0].item<float>(), 0.5f, 1e-6);
  EXPECT_NEAR(out.cost[0][2][0][0].item<float>(), 1.0f, 1e-6);
  EXPECT_FALSE(out.inside[0][0][0][0].item<bool>());
  EXPECT_FALSE(out.inside[0][1][0][0].item<bool>());
  EXPECT_TRUE(out.inside[0][2][0][0].item<bool>());

  // Far away and non-finite positions read exactly 0, never NaN.
  const torch::Tensor far = torch::tensor({1e30f, std::nanf("")}).view({1, 2, 1, 1});
  const torch::Tensor far_cost = corr.Lookup(ref, far, dir, eflow).cost;
  EXPECT_TRUE(torch::all(far_cost == 0).item<bool>());
  // No NaN in the fused pass's gradient either (the ATen ops' grid_sample
  // backward is PyTorch's business).
  if (GetParam() == Path::kFusedTraining) {
    corr.Lookup(ref, far, dir, eflow).cost.sum().backward();
    EXPECT_TRUE(torch::all(torch::isfinite(ones.grad())).item<bool>());
    EXPECT_TRUE(torch::all(torch::isfinite(ref.grad())).item<bool>());
  }
}

INSTANTIATE_TEST_SUITE_P(AtenAndFused, EpipolarCorrelationPathTest,
                         ::testing::Values(Path::kAtenOps, Path::kFusedInference,
                                           Path::kFusedTraining),
                         [](const ::testing::TestParamInfo<Path>& info) {
                           switch (info.param) {
                             case Path::kAtenOps: return std::string("AtenOps");
                             case Path::kFusedInference: return std::string("FusedInference");
                             case Path::kFusedTraining: return std::string("FusedTraining");
                           }
                           return std::string();
                         });

// The two paths against each other at a realistic size (48 channels, two
// levels, a match partly off the map), including a reference feature map
// with non-contiguous strides, as the network's repeated maps can be.
TEST(EpipolarCorrelationTest, FusedInferenceEqualsAtenOps) {
  torch::manual_seed(3);
  const int64_t B = 3, C = 48, H = 30, W = 40, h = 30, w = 40;
  const torch::Tensor source = torch::randn({B, C, H, W});
  const torch::Tensor ref = torch::randn({B, w, h, C}).permute({0, 3, 2, 1});
  const torch::Tensor base = torch::rand({B, 2, h, w}) * 50.0 - 5.0;
  const torch::Tensor angle = torch::rand({B, 1, h, w}) * 6.283;
  const torch::Tensor dir = torch::cat({torch::cos(angle), torch::sin(angle)}, 1);
  const torch::Tensor eflow = torch::randn({B, 1, h, w}) * 3.0;
  const CorrelationSamples aten =
      EpipolarCorrelation(source, 2, 5, CorrelationImpl::kAtenOps).Lookup(ref, base, dir, eflow);
  torch::NoGradGuard no_grad;
  const CorrelationSamples fused = EpipolarCorrelation(source, 2, 5).Lookup(ref, base, dir, eflow);
  EXPECT_TRUE(torch::equal(fused.inside, aten.inside));
  EXPECT_LT((fused.cost - aten.cost).abs().max().item<float>(), 1e-5f);
  EXPECT_GT(aten.cost.abs().mean().item<float>(), 0.01f);  // not a comparison of zeros
}

// Training's lookup: the fused node's gradients w.r.t. the source features
// (through the pooled pyramid and the channels-last copies) and the
// reference features, against PyTorch's grid_sample backward, at a
// realistic size with matches partly off the map and a reference with
// non-contiguous strides. The gradient weights every output differently, so
// a sample's gradient sent to the wrong corner or level shows.
TEST(EpipolarCorrelationTest, FusedTrainingGradientsEqualAtenOps) {
  torch::manual_seed(5);
  const int64_t B = 3, C = 48, H = 30, W = 40, h = 30, w = 40, levels = 2, samples = 5;
  const torch::Tensor source_values = torch::randn({B, C, H, W});
  const torch::Tensor ref_values = torch::randn({B, w, h, C});
  const torch::Tensor base = torch::rand({B, 2, h, w}) * 50.0 - 5.0;
  const torch::Tensor angle = torch::rand({B, 1, h, w}) * 6.283;
  const torch::Tensor dir = torch::cat({torch::cos(angle), torch::sin(angle)}, 1);
  const torch::Tensor eflow = torch::randn({B, 1, h, w}) * 3.0;
  const torch::Tensor weights = torch::randn({B, levels * samples, h, w});
  struct Result {
    torch::Tensor cost, source_grad, ref_grad;
    std::string node;
  };
  const auto run = [&](CorrelationImpl impl) {
    torch::Tensor source = source_values.clone().requires_grad_(true);
    torch::Tensor ref_leaf = ref_values.clone().requires_grad_(true);
    const torch::Tensor ref = ref_leaf.permute({0, 3, 2, 1});  // [B,C,h,w], not contiguous
    const torch::Tensor cost =
        EpipolarCorrelation(source, levels, samples, impl).Lookup(ref, base, dir, eflow).cost;
    (cost * weights).sum().backward();
    return Result{cost.detach(), source.grad(), ref_leaf.grad().permute({0, 3, 2, 1}),
                  cost.grad_fn() ? cost.grad_fn()->name() : std::string()};
  };
  const Result aten = run(CorrelationImpl::kAtenOps);
  const Result fused = run(CorrelationImpl::kAuto);
  EXPECT_NE(fused.node.find("LookupFunction"), std::string::npos) << fused.node;
  EXPECT_EQ(aten.node.find("LookupFunction"), std::string::npos) << aten.node;
  EXPECT_LT((fused.cost - aten.cost).abs().max().item<float>(), 1e-5f);
  const auto relative = [](const torch::Tensor& a, const torch::Tensor& b) {
    return ((a - b).abs().max() / b.abs().max()).item<float>();
  };
  EXPECT_GT(aten.source_grad.abs().max().item<float>(), 0.01f);  // not a comparison of zeros
  EXPECT_GT(aten.ref_grad.abs().max().item<float>(), 0.01f);
  EXPECT_LT(relative(fused.source_grad, aten.source_grad), 1e-5f);
  EXPECT_LT(relative(fused.ref_grad, aten.ref_grad), 1e-5f);
}

TEST(EpipolarCorrelationTest, FusedLookupRefusesAGradientToTheMatch) {
  const torch::Tensor level = torch::randn({1, 2, 2, 3}).requires_grad_(true);
  const torch::Tensor ref = torch::randn({1, 3, 1, 1});
  const torch::Tensor match = torch::zeros({1, 2, 1, 1}).requires_grad_(true);
  const torch::Tensor dir = torch::zeros({1, 2, 1, 1});
  EXPECT_FALSE(CanUseFusedCorrelation(level, ref, match, dir));
  EXPECT_THROW(FusedCorrelationLookup({level}, ref, match, dir, 3), std::invalid_argument);
  torch::NoGradGuard no_grad;  // inference: no gradient anywhere, so the pass serves
  EXPECT_TRUE(CanUseFusedCorrelation(level, ref, match, dir));
  EXPECT_EQ(FusedCorrelationLookup({level}, ref, match, dir, 3).sizes(),
            torch::IntArrayRef({1, 3, 1, 1}));
}

TEST(EpipolarCorrelationTest, GradientReachesEflowAndFeatures) {
  const torch::Tensor ramp = torch::arange(8, torch::kFloat).view({1, 1, 1, 8}).expand({1, 1, 8, 8}).contiguous();
  torch::Tensor src = ramp.clone().requires_grad_(true);
  const EpipolarCorrelation corr(src, 2, 3);
  const torch::Tensor ref = torch::full({1, 1, 1, 1}, 2.0f).requires_grad_(true);
  const torch::Tensor base = torch::tensor({3.25f, 3.0f}).view({1, 2, 1, 1});
  const torch::Tensor dir = torch::tensor({0.6f, 0.8f}).view({1, 2, 1, 1});
  torch::Tensor eflow = torch::zeros({1, 1, 1, 1}).requires_grad_(true);
  // Level-0 centre sample: cost = 2 * x = 2 * (3.25 + 0.6 e); d/de = 1.2.
  corr.Lookup(ref, base, dir, eflow).cost[0][1][0][0].backward();
  EXPECT_NEAR(eflow.grad().item<float>(), 1.2f, 1e-5);
  EXPECT_NEAR(ref.grad().item<float>(), 3.25f, 1e-5);
  EXPECT_GT(src.grad().abs().sum().item<float>(), 0.0f);
}

TEST(EpipolarCorrelationTest, RejectsBadInput) {
  EXPECT_THROW(EpipolarCorrelation(torch::zeros({2, 3, 4}), 1, 3), std::invalid_argument);
  EXPECT_THROW(EpipolarCorrelation(torch::zeros({1, 3, 4, 4}), 0, 3), std::invalid_argument);
  EXPECT_THROW(EpipolarCorrelation(torch::zeros({1, 3, 4, 4}), 2, 0), std::invalid_argument);
  const EpipolarCorrelation corr(torch::zeros({1, 3, 4, 4}), 2, 3);
  const torch::Tensor xy = torch::zeros({1, 2, 2, 2});
  const torch::Tensor e = torch::zeros({1, 1, 2, 2});
  EXPECT_THROW(corr.Lookup(torch::zeros({1, 4, 2, 2}), xy, xy, e), std::invalid_argument);
  EXPECT_THROW(corr.Lookup(torch::zeros({1, 3, 2, 2}), torch::zeros({1, 2, 2, 3}), xy, e),
               std::invalid_argument);
  EXPECT_THROW(corr.Lookup(torch::zeros({1, 3, 2, 2}), xy, xy, torch::zeros({1, 2, 2, 2})),
               std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
