#include "model/nearest_plane.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <vector>

#include <torch/torch.h>

namespace dispmvs::model {
namespace {

using torch::indexing::Slice;

constexpr int64_t kH = 30, kW = 40;

TEST(NearestPlaneTest, NearestAnchorIsAtTheSmallestChessboardDistance) {
  torch::manual_seed(5);
  torch::Tensor anchor = torch::rand({3, 1, 17, 23}) < 0.04;
  anchor[1].fill_(false);  // an image without anchors
  anchor[2].fill_(false);
  anchor[2][0][16][0] = true;  // one anchor in a corner
  const torch::Tensor nearest = NearestAnchor(anchor);
  ASSERT_EQ(nearest.scalar_type(), torch::kLong);
  EXPECT_TRUE((nearest[1] == -1).all().item<bool>());
  EXPECT_TRUE((nearest[2] == 16 * 23).all().item<bool>());
  ASSERT_GT(anchor[0].sum().item<int64_t>(), 3);
  for (int64_t i = 0; i < 17; ++i) {
    for (int64_t j = 0; j < 23; ++j) {
      int64_t best = 1 << 30;
      for (int64_t y = 0; y < 17; ++y) {
        for (int64_t x = 0; x < 23; ++x) {
          if (anchor[0][0][y][x].item<bool>()) best = std::min(best, std::max(std::abs(y - i), std::abs(x - j)));
        }
      }
      const int64_t q = nearest[0][0][i][j].item<int64_t>();
      ASSERT_GE(q, 0);
      EXPECT_TRUE(anchor[0][0][q / 23][q % 23].item<bool>());
      EXPECT_EQ(std::max(std::abs(q / 23 - i), std::abs(q % 23 - j)), best) << i << "," << j;
    }
  }
}

TEST(NearestPlaneTest, NearestAnchorsAlongAxesAreTheNearestOnEachSide) {
  torch::manual_seed(7);
  torch::Tensor anchor = torch::rand({2, 1, 13, 19}) < 0.08;
  anchor[1].fill_(false);  // an image without anchors
  const auto along = NearestAnchorsAlongAxes(anchor);
  for (const auto& t : along) {
    ASSERT_EQ(t.scalar_type(), torch::kLong);
    ASSERT_EQ(t.sizes(), anchor.sizes());
    EXPECT_TRUE((t[1] == -1).all().item<bool>());
  }
  ASSERT_GT(anchor[0].sum().item<int64_t>(), 5);
  const auto a = anchor.accessor<bool, 4>();
  for (int64_t i = 0; i < 13; ++i) {
    for (int64_t j = 0; j < 19; ++j) {
      // Walk from the pixel to each side until an anchor: the expected index.
      const int64_t steps[4][2] = {{0, -1}, {0, 1}, {-1, 0}, {1, 0}};
      for (int side = 0; side < 4; ++side) {
        int64_t want = -1;
        for (int64_t y = i, x = j; y >= 0 && y < 13 && x >= 0 && x < 19; y += steps[side][0], x += steps[side][1]) {
          if (a[0][0][y][x]) {
            want = y * 19 + x;
            break;
          }
        }
        EXPECT_EQ(along[side][0][0][i][j].item<int64_t>(), want) << "side " << side << " at " << i << "," << j;
      }
    }
  }
}

TEST(NearestPlaneTest, ExtendNearestPlaneIsExactOnAPlane) {
  // w = 0.3 + 0.004 x - 0.002 y, the slopes given exactly, anchors in one
  // block: the extension reproduces the plane everywhere.
  const torch::Tensor x = torch::arange(kW, torch::kFloat32).view({1, 1, 1, kW}).expand({1, 1, kH, kW});
  const torch::Tensor y = torch::arange(kH, torch::kFloat32).view({1, 1, kH, 1}).expand({1, 1, kH, kW});
  const torch::Tensor plane = 0.3 + 0.004 * x - 0.002 * y;
  torch::Tensor anchor = torch::zeros({1, 1, kH, kW}, torch::kBool);
  anchor.index_put_({0, 0, Slice(10, 20), Slice(25, 35)}, true);
  const torch::Tensor w = torch::where(anchor, plane, torch::zeros_like(plane));
  const torch::Tensor extended = ExtendNearestPlane(w, torch::full_like(w, 0.004f), torch::full_like(w, -0.002f),
                                                    NearestAnchor(anchor));
  EXPECT_LT((extended - plane).abs().max().item<float>(), 1e-6f);
  // No anchor: 0 everywhere.
  const torch::Tensor none = ExtendNearestPlane(w, torch::zeros_like(w), torch::zeros_like(w),
                                                NearestAnchor(torch::zeros_like(anchor)));
  EXPECT_EQ(none.abs().max().item<float>(), 0.0f);
}

TEST(NearestPlaneTest, ExtendNearestPlaneLoopIsTheOperations) {
  // Random planes at random anchors over two batch items, one without
  // anchors: the CPU loop and the operations give the same maps.
  torch::manual_seed(3);
  const torch::Tensor anchor = torch::rand({2, 1, kH, kW}) < 0.05;
  anchor[1].fill_(false);
  const torch::Tensor w = 0.2 + torch::rand({2, 1, kH, kW});
  const torch::Tensor gx = 0.01 * torch::randn({2, 1, kH, kW});
  const torch::Tensor gy = 0.01 * torch::randn({2, 1, kH, kW});
  const torch::Tensor nearest = NearestAnchor(anchor);
  const torch::Tensor loop = ExtendNearestPlane(w, gx, gy, nearest);
  const torch::Tensor ops = ExtendNearestPlaneByOps(w, gx, gy, nearest);
  EXPECT_LT((loop - ops).abs().max().item<float>(), 1e-6f);
  EXPECT_EQ(loop[1].abs().max().item<float>(), 0.0f);
  // Within bounds: clamped, and 0 where the plane is not positive.
  const torch::Tensor low = torch::full({2, 1, 1, 1}, 0.5f), high = torch::full({2, 1, 1, 1}, 0.9f);
  const torch::Tensor within = ExtendNearestPlaneWithin(w, gx, gy, nearest, low, high);
  const torch::Tensor want = torch::where((nearest >= 0) & (loop > 0), torch::clamp(loop, 0.5, 0.9),
                                          torch::zeros_like(loop));
  EXPECT_TRUE(torch::equal(within, want));
}

TEST(NearestPlaneTest, ExtendTrustedPlanesStopsAtTheBoundsAndBehindTheCamera) {
  // w = 0.3 - 0.01 x from trusted columns 0-9: the plane falls to 0 at
  // column 30 and below beyond; within [0.1, 0.3] it is the plane, below
  // 0.1 the bound, beyond column 30 nothing (0; column 30 itself is left
  // out: its plane is 0 only up to rounding).
  const torch::Tensor x = torch::arange(kW, torch::kFloat32).view({1, 1, 1, kW}).expand({1, 1, kH, kW});
  const torch::Tensor plane = 0.3 - 0.01 * x;
  const torch::Tensor trusted = x < 10;
  const torch::Tensor low = torch::full({1, 1, 1, 1}, 0.1f), high = torch::full({1, 1, 1, 1}, 0.3f);
  const torch::Tensor extended =
      ExtendTrustedPlanes(torch::where(trusted, plane, torch::zeros_like(plane)), trusted, 4, low, high, 0.0);
  const torch::Tensor expected =
      torch::where(x > 30, torch::zeros_like(plane), torch::clamp(plane, 0.1, 0.3));
  EXPECT_LT((extended - expected).abs().masked_select(x != 30).max().item<float>(), 1e-5f);
}

TEST(NearestPlaneTest, RejectsBadInput) {
  EXPECT_THROW(NearestAnchor(torch::ones({1, 1, 4, 4})), std::invalid_argument);
  EXPECT_THROW(NearestAnchor(torch::ones({1, 4, 4}, torch::kBool)), std::invalid_argument);
  EXPECT_THROW(NearestAnchorsAlongAxes(torch::ones({1, 1, 4, 4})), std::invalid_argument);
  const torch::Tensor f = torch::zeros({1, 1, 4, 4});
  const torch::Tensor index = torch::zeros({1, 1, 4, 4}, torch::kLong);
  EXPECT_THROW(ExtendNearestPlane(f, f, f, index.to(torch::kInt)), std::invalid_argument);
  EXPECT_THROW(ExtendNearestPlane(f, f, torch::zeros({1, 1, 4, 5}), index), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
