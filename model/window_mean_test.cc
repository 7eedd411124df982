#include "model/window_mean.h"

#include <gtest/gtest.h>

#include <torch/torch.h>

namespace dispmvs::model {
namespace {

// The reference: LibTorch's average pooling over the clipped window.
torch::Tensor PooledMean(const torch::Tensor& x, int64_t r) {
  return torch::avg_pool2d(x, {2 * r + 1, 2 * r + 1}, {1, 1}, {r, r}, /*ceil_mode=*/false,
                           /*count_include_pad=*/false);
}

TEST(WindowMeanTest, EqualsClippedAveragePoolingOnTheCpuAndOnTheSlicePath) {
  torch::manual_seed(3);
  // Sizes around the window's: smaller than it, equal, larger, odd shapes.
  for (const auto& [h, w] : std::vector<std::pair<int64_t, int64_t>>{{1, 1}, {3, 9}, {7, 7}, {20, 31}, {48, 64}}) {
    for (const int64_t r : {0, 1, 3, 5}) {
      const torch::Tensor x = torch::rand({2, 3, h, w});
      const torch::Tensor expected = PooledMean(x.to(torch::kFloat64), r);
      EXPECT_TRUE(torch::allclose(WindowMean(x, r).to(torch::kFloat64), expected, 1e-6, 1e-6))
          << h << "x" << w << " r " << r;
      // float64 takes the other path (slices of the padded image).
      EXPECT_TRUE(torch::allclose(WindowMean(x.to(torch::kFloat64), r), expected, 1e-12, 1e-12))
          << h << "x" << w << " r " << r;
    }
  }
}

TEST(WindowMeanTest, WindowsLargerThanTheImageAverageWhatIsInside) {
  // Brute force on a 2x3 image with r = 4: every window holds the whole image.
  const torch::Tensor x = torch::arange(6, torch::kFloat32).view({1, 1, 2, 3});
  const torch::Tensor mean = WindowMean(x, 4);
  EXPECT_TRUE(torch::allclose(mean, torch::full_like(x, 2.5f)));
  // r = 1 at the corner (0, 0): pixels (0,0), (0,1), (1,0), (1,1) = 0, 1, 3, 4.
  EXPECT_FLOAT_EQ(WindowMean(x, 1)[0][0][0][0].item<float>(), 2.0f);
  EXPECT_FLOAT_EQ(WindowMean(x.to(torch::kFloat64), 1)[0][0][0][0].item<double>(), 2.0);
}

TEST(WindowMeanTest, LongLinesDoNotDrift) {
  // Running sums over 4000 large values, then a single spike far away.
  torch::Tensor x = torch::full({1, 1, 3, 4000}, 1000.0f);
  x[0][0][1][3990] = 1001.0f;
  const torch::Tensor mean = WindowMean(x, 2);
  EXPECT_FLOAT_EQ(mean[0][0][1][100].item<float>(), 1000.0f);
  EXPECT_NEAR(mean[0][0][1][3990].item<float>(), 1000.0f + 1.0f / 15.0f, 1e-3);
}

TEST(WindowMeanTest, RefusesBadShapesAndRadii) {
  EXPECT_THROW(WindowMean(torch::zeros({3, 4}), 1), std::invalid_argument);
  EXPECT_THROW(WindowMean(torch::zeros({1, 1, 3, 4}), -1), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
