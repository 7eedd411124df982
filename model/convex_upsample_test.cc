#include "model/convex_upsample.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace dispmvs::model {
namespace {

constexpr int64_t kCentre = 4;  // neighbour index of (dy, dx) = (0, 0)

// Logits that give all weight to neighbour choose(i, j) for sub-pixel (i, j):
// exp(-1e4) underflows to exactly 0, so the softmax is exactly one-hot.
template <class Choose>
torch::Tensor OneHotLogits(int64_t batch, int64_t height, int64_t width, int64_t f, Choose choose) {
  torch::Tensor logits = torch::full({batch, 9 * f * f, height, width}, -1e4);
  for (int64_t i = 0; i < f; ++i) {
    for (int64_t j = 0; j < f; ++j) {
      logits.select(1, choose(i, j) * f * f + i * f + j).fill_(0.0);
    }
  }
  return logits;
}

TEST(ConvexUpsampleTest, OutputShape) {
  const torch::Tensor x = torch::randn({2, 3, 5, 7});
  EXPECT_EQ(ConvexUpsample(x, torch::randn({2, 9 * 16, 5, 7}), 4).sizes(),
            (std::vector<int64_t>{2, 3, 20, 28}));
  EXPECT_EQ(ConvexUpsample(x, torch::randn({2, 9 * 4, 5, 7}), 2).sizes(),
            (std::vector<int64_t>{2, 3, 10, 14}));
  EXPECT_EQ(ConvexUpsample(x, torch::randn({2, 9, 5, 7}), 1).sizes(),
            (std::vector<int64_t>{2, 3, 5, 7}));
}

TEST(ConvexUpsampleTest, ConstantStaysConstantIncludingTheBorder) {
  torch::manual_seed(1);
  const double value = 0.37;  // e.g. an inverse depth
  const torch::Tensor x = torch::full({2, 1, 6, 5}, value);
  const torch::Tensor logits = 10 * torch::randn({2, 9 * 16, 6, 5});
  const torch::Tensor up = ConvexUpsample(x, logits, 4);
  // Each output is sum_k w_k * value with sum_k w_k = 1 up to float rounding
  // (9 terms: a few ulp). Zero padding would give value * (1 - w_outside)
  // on the border, off by up to the whole value.
  EXPECT_LE((up - value).abs().max().item<double>(), value * 1e-6);
}

TEST(ConvexUpsampleTest, CentreOnlyMaskIsNearestUpsampling) {
  torch::manual_seed(2);
  const int64_t f = 4;
  const torch::Tensor x = torch::randn({2, 3, 4, 5});
  const torch::Tensor up =
      ConvexUpsample(x, OneHotLogits(2, 4, 5, f, [](int64_t, int64_t) { return kCentre; }), f);
  const torch::Tensor nearest = x.repeat_interleave(f, 2).repeat_interleave(f, 3);
  EXPECT_TRUE(torch::equal(up, nearest));
}

// Checks the channel layout of the mask (k * f * f + i * f + j) and the
// border replication against an index-by-index expectation.
TEST(ConvexUpsampleTest, EachSubPixelTakesItsChosenNeighbour) {
  torch::manual_seed(3);
  const int64_t f = 3, height = 4, width = 5;
  const auto choose = [](int64_t i, int64_t j) { return (i * 3 + j * 2) % 9; };
  const torch::Tensor x = torch::randn({1, 2, height, width});
  const torch::Tensor up = ConvexUpsample(x, OneHotLogits(1, height, width, f, choose), f);
  const auto clamp = [](int64_t v, int64_t n) { return v < 0 ? 0 : (v >= n ? n - 1 : v); };
  for (int64_t c = 0; c < 2; ++c) {
    for (int64_t h = 0; h < height; ++h) {
      for (int64_t w = 0; w < width; ++w) {
        for (int64_t i = 0; i < f; ++i) {
          for (int64_t j = 0; j < f; ++j) {
            const int64_t k = choose(i, j);
            const int64_t src_h = clamp(h + k / 3 - 1, height);
            const int64_t src_w = clamp(w + k % 3 - 1, width);
            EXPECT_EQ(up[0][c][h * f + i][w * f + j].item<float>(),
                      x[0][c][src_h][src_w].item<float>())
                << "c=" << c << " h=" << h << " w=" << w << " i=" << i << " j=" << j;
          }
        }
      }
    }
  }
}

TEST(ConvexUpsampleTest, GradientsMatchFiniteDifferences) {
  torch::manual_seed(4);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  const torch::Tensor x = torch::randn({1, 2, 3, 3}, opts).requires_grad_(true);
  const torch::Tensor logits = torch::randn({1, 9 * 4, 3, 3}, opts).requires_grad_(true);
  const torch::Tensor probe = torch::randn({1, 2, 6, 6}, opts);
  const auto loss = [&](const torch::Tensor& a, const torch::Tensor& b) {
    return (ConvexUpsample(a, b, 2) * probe).sum();
  };
  loss(x, logits).backward();
  ASSERT_TRUE(x.grad().defined());
  ASSERT_TRUE(logits.grad().defined());
  EXPECT_GT(x.grad().abs().sum().item<double>(), 0.0);
  EXPECT_GT(logits.grad().abs().sum().item<double>(), 0.0);

  torch::NoGradGuard no_grad;
  const double eps = 1e-6;
  for (const int64_t index : {0, 4, 8, 13, 17}) {
    torch::Tensor xp = x.detach().clone();
    xp.view(-1)[index] += eps;
    torch::Tensor xm = x.detach().clone();
    xm.view(-1)[index] -= eps;
    const double numeric = (loss(xp, logits) - loss(xm, logits)).item<double>() / (2 * eps);
    EXPECT_NEAR(x.grad().view(-1)[index].item<double>(), numeric, 1e-6);
  }
  for (const int64_t index : {0, 50, 100, 200, 323}) {
    torch::Tensor lp = logits.detach().clone();
    lp.view(-1)[index] += eps;
    torch::Tensor lm = logits.detach().clone();
    lm.view(-1)[index] -= eps;
    const double numeric = (loss(x, lp) - loss(x, lm)).item<double>() / (2 * eps);
    EXPECT_NEAR(logits.grad().view(-1)[index].item<double>(), numeric, 1e-6);
  }
}

TEST(ConvexUpsampleTest, RejectsBadShapes) {
  const torch::Tensor x = torch::randn({1, 2, 3, 4});
  EXPECT_THROW(ConvexUpsample(x, torch::randn({1, 9 * 16, 3, 4}), 2), std::invalid_argument);
  EXPECT_THROW(ConvexUpsample(x, torch::randn({1, 9 * 4, 4, 3}), 2), std::invalid_argument);
  EXPECT_THROW(ConvexUpsample(x, torch::randn({2, 9 * 4, 3, 4}), 2), std::invalid_argument);
  EXPECT_THROW(ConvexUpsample(x, torch::randn({1, 9, 3, 4}), 0), std::invalid_argument);
  EXPECT_THROW(ConvexUpsample(torch::randn({2, 3, 4}), torch::randn({1, 9, 3, 4}), 1),
               std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
