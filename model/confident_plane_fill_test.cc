#include "model/confident_plane_fill.h"

#include <gtest/gtest.h>

#include <stdexcept>

#include <torch/torch.h>

namespace dispmvs::model {
namespace {

using torch::indexing::Slice;

constexpr int64_t kH = 40, kW = 60;

// Inverse depth on a plane, w = 0.25 + 0.002 x - 0.001 y (depths 3.1 to 5.3).
torch::Tensor PlaneInverseDepth() {
  const torch::Tensor x = torch::arange(kW, torch::kFloat32).view({1, 1, 1, kW}).expand({1, 1, kH, kW});
  const torch::Tensor y = torch::arange(kH, torch::kFloat32).view({1, 1, kH, 1}).expand({1, 1, kH, kW});
  return 0.25 + 0.002 * x - 0.001 * y;
}

TEST(ConfidentPlaneFillTest, LowConfidencePixelsTakeTheConfidentPlane) {
  const torch::Tensor truth = PlaneInverseDepth().reciprocal();
  // Confident on the left 20 columns; little chance on the right 30, their
  // depth 20 % too near (inverse depth 25 % off, within max_change 0.3),
  // except rows 30-39 at half the depth (100 % off: another surface, left
  // alone); in between, neither (0.6): kept as it is.
  torch::Tensor confidence = torch::full({1, 1, kH, kW}, 0.6f);
  confidence.index_put_({0, 0, Slice(), Slice(0, 20)}, 0.9f);
  confidence.index_put_({0, 0, Slice(), Slice(30, kW)}, 0.1f);
  torch::Tensor depth = torch::where(confidence < 0.5, truth * 0.8, truth);
  depth.index_put_({0, 0, Slice(30, kH), Slice(30, kW)}, truth.index({0, 0, Slice(30, kH), Slice(30, kW)}) * 0.5);
  depth.index_put_({0, 0, Slice(0, 3), Slice(50, kW)}, 0.0f);  // no depth: stays none
  ConfidentPlaneFillOptions options;
  options.below = 0.5;
  options.max_change = 0.3;
  const ConfidentPlaneFill fill = FillFromConfidentPlanes(depth, confidence, options);
  torch::Tensor low = (confidence < 0.5) & (depth > 0);
  low.index_put_({0, 0, Slice(30, kH), Slice()}, false);
  EXPECT_TRUE(torch::equal(fill.filled, low));
  // The plane, extended over 11 to 40 columns: exact to float rounding (the
  // slopes are fitted to exact plane values).
  const torch::Tensor error = ((fill.depth - truth) / truth).abs();
  EXPECT_LT(error.masked_select(low).max().item<float>(), 1e-4f);
  EXPECT_TRUE(torch::equal(fill.depth.masked_select(~low), depth.masked_select(~low)));
  EXPECT_EQ(fill.depth.index({0, 0, Slice(0, 3), Slice(50, kW)}).abs().max().item<float>(), 0.0f);
  // Any change allowed: rows 30-39 too.
  options.max_change = 0;
  const ConfidentPlaneFill unbounded = FillFromConfidentPlanes(depth, confidence, options);
  EXPECT_TRUE(torch::equal(unbounded.filled, (confidence < 0.5) & (depth > 0)));
  // A higher anchor than any pixel has: no plane to take.
  options.anchor = 0.95;
  const ConfidentPlaneFill nothing = FillFromConfidentPlanes(depth, confidence, options);
  EXPECT_FALSE(nothing.filled.any().item<bool>());
  EXPECT_TRUE(torch::equal(nothing.depth, depth));
  // Off by default.
  EXPECT_FALSE(FillFromConfidentPlanes(depth, confidence, {}).filled.any().item<bool>());
}

TEST(ConfidentPlaneFillTest, KeepsFilledDepthsWithinTheMapsRange) {
  // A steep plane from 8 confident columns: extended over 52 more columns it
  // would leave the depths the map holds; it stops at their bounds (any
  // change allowed here).
  const torch::Tensor x = torch::arange(kW, torch::kFloat32).view({1, 1, 1, kW}).expand({1, 1, kH, kW});
  const torch::Tensor w = 0.5 - 0.02 * x;  // 0 at column 25, negative beyond
  torch::Tensor confidence = torch::full({1, 1, kH, kW}, 0.1f);
  confidence.index_put_({0, 0, Slice(), Slice(0, 8)}, 0.9f);
  const torch::Tensor depth = torch::where(x < 8, w.reciprocal(), torch::full_like(w, 4.0f));
  ConfidentPlaneFillOptions any_change;
  any_change.below = 0.5;
  const ConfidentPlaneFill fill = FillFromConfidentPlanes(depth, confidence, any_change);
  const float near = depth.min().item<float>(), far = depth.max().item<float>();
  EXPECT_GE(fill.depth.min().item<float>(), near * (1 - 1e-6f));
  EXPECT_LE(fill.depth.max().item<float>(), far * (1 + 1e-6f));
  EXPECT_TRUE(torch::isfinite(fill.depth).all().item<bool>());
  // Where the plane still lies within the range, it is the plane.
  const torch::Tensor inside = (x >= 8) & (w >= 1.0 / far);
  EXPECT_LT(((fill.depth - w.reciprocal()) / w.reciprocal()).abs().masked_select(inside).max().item<float>(), 1e-4f);
}

TEST(ConfidentPlaneFillTest, RejectsBadInput) {
  const torch::Tensor depth = torch::ones({1, 1, 4, 4});
  EXPECT_THROW(FillFromConfidentPlanes(depth, torch::ones({1, 1, 4, 5}), {}), std::invalid_argument);
  EXPECT_THROW(FillFromConfidentPlanes(torch::ones({1, 4, 4}), torch::ones({1, 4, 4}), {}),
               std::invalid_argument);
  ConfidentPlaneFillOptions bad;
  bad.below = 1.0;
  EXPECT_THROW(FillFromConfidentPlanes(depth, depth, bad), std::invalid_argument);
  bad = {};
  bad.below = -0.1;
  EXPECT_THROW(FillFromConfidentPlanes(depth, depth, bad), std::invalid_argument);
  bad = {};
  bad.anchor = bad.below;
  EXPECT_THROW(FillFromConfidentPlanes(depth, depth, bad), std::invalid_argument);
  bad = {};
  bad.slope_radius = 0;
  EXPECT_THROW(FillFromConfidentPlanes(depth, depth, bad), std::invalid_argument);
  bad = {};
  bad.max_change = -1;
  EXPECT_THROW(FillFromConfidentPlanes(depth, depth, bad), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
