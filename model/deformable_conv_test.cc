#include "model/deformable_conv.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace dispmvs::model {
namespace {
namespace F = torch::nn::functional;

// The regular 3x3 conv (padding 1) with the deformable layer's weights.
torch::Tensor RegularConv(DeformableConv2d& layer, const torch::Tensor& x) {
  return F::conv2d(x, layer->weight(), F::Conv2dFuncOptions().bias(layer->bias()).padding(1));
}

// Offsets [B,18,H,W] shifting every tap by (dx, dy).
torch::Tensor ConstantOffsets(const torch::Tensor& x, double dx, double dy) {
  torch::Tensor offsets = torch::zeros({x.size(0), 18, x.size(2), x.size(3)});
  for (int64_t tap = 0; tap < 9; ++tap) {
    offsets.select(1, 2 * tap).fill_(dx);
    offsets.select(1, 2 * tap + 1).fill_(dy);
  }
  return offsets;
}

double MaxAbsDiff(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>();
}

TEST(DeformableConv2dTest, FreshLayerIsARegularConv) {
  torch::manual_seed(10);
  DeformableConv2d layer(5, 7);
  for (const auto& size : {std::vector<int64_t>{2, 5, 9, 11}, std::vector<int64_t>{1, 5, 1, 6},
                           std::vector<int64_t>{1, 5, 4, 1}}) {
    const torch::Tensor x = torch::randn(size);
    const torch::Tensor out = layer->forward(x);
    ASSERT_EQ(out.sizes(), RegularConv(layer, x).sizes());
    EXPECT_LE(MaxAbsDiff(out, RegularConv(layer, x)), 1e-5) << x.sizes();
  }
}

TEST(DeformableConv2dTest, IntegerOffsetShiftsTheConv) {
  torch::manual_seed(11);
  DeformableConv2d layer(4, 3);
  const torch::Tensor x = torch::randn({2, 4, 8, 10});
  const torch::Tensor conv = RegularConv(layer, x);
  const int64_t h = x.size(2), w = x.size(3);

  // Every tap reads one column to the right: out(i, j) = conv(i, j + 1).
  const torch::Tensor right = layer->forward_with_offsets(x, ConstantOffsets(x, 1.0, 0.0));
  EXPECT_LE(MaxAbsDiff(right.narrow(3, 0, w - 1), conv.narrow(3, 1, w - 1)), 1e-5);

  // One row down: out(i, j) = conv(i + 1, j).
  const torch::Tensor down = layer->forward_with_offsets(x, ConstantOffsets(x, 0.0, 1.0));
  EXPECT_LE(MaxAbsDiff(down.narrow(2, 0, h - 1), conv.narrow(2, 1, h - 1)), 1e-5);

  // Half a column: bilinear sampling is linear, so out(i, j) is the mean of
  // conv(i, j) and conv(i, j + 1) (interior, away from the zero padding).
  const torch::Tensor half = layer->forward_with_offsets(x, ConstantOffsets(x, 0.5, 0.0));
  const torch::Tensor expected = 0.5 * (conv.narrow(3, 1, w - 3) + conv.narrow(3, 2, w - 3));
  EXPECT_LE(MaxAbsDiff(half.narrow(3, 1, w - 3), expected), 1e-5);
}

TEST(DeformableConv2dTest, GradientsReachTheOffsetConv) {
  torch::manual_seed(12);
  DeformableConv2d layer(3, 4);
  const torch::Tensor x = torch::randn({1, 3, 6, 7});
  const torch::Tensor probe = torch::randn({1, 4, 6, 7});
  (layer->forward(x) * probe).sum().backward();
  for (const auto& item : layer->named_parameters()) {
    ASSERT_TRUE(item.value().grad().defined()) << item.key();
    EXPECT_GT(item.value().grad().abs().sum().item<double>(), 0.0) << item.key();
  }
  EXPECT_GT(layer->offset_conv()->weight.grad().abs().sum().item<double>(), 0.0);
}

TEST(DeformableConv2dTest, RejectsBadShapes) {
  DeformableConv2d layer(3, 4);
  EXPECT_THROW(layer->forward(torch::randn({1, 2, 5, 5})), std::invalid_argument);
  EXPECT_THROW(layer->forward(torch::randn({3, 5, 5})), std::invalid_argument);
  EXPECT_THROW(layer->forward_with_offsets(torch::randn({1, 3, 5, 5}), torch::zeros({1, 18, 5, 4})),
               std::invalid_argument);
  EXPECT_THROW(DeformableConv2d(0, 4), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
