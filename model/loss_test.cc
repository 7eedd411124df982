#include "model/loss.h"

#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

namespace dispmvs::model {
namespace {

// Range [1, 2]: inverse depth in [0.5, 1], normalised as (w - 0.5) / 0.5.
struct Fixture {
  torch::Tensor d_min = torch::tensor({1.0f});
  torch::Tensor d_max = torch::tensor({2.0f});
  torch::Tensor gt = torch::tensor({1.0f, 2.0f}).view({1, 1, 1, 2});  // norm: 1, 0
  torch::Tensor pred0 = torch::tensor({0.75f, 0.5f}).view({1, 1, 1, 2});  // norm: 0.5, 0
  torch::Tensor pred1 = torch::tensor({1.0f, 0.75f}).view({1, 1, 1, 2});  // norm: 1, 0.5
};

TEST(SequenceLossTest, HandComputedValue) {
  Fixture f;
  const torch::Tensor all_valid = torch::ones({1, 1, 1, 2}, torch::kBool);
  // Per-iteration L1 means: 0.25 and 0.25; weights gamma^1 and gamma^0.
  EXPECT_NEAR(SequenceLoss({f.pred0, f.pred1}, f.gt, all_valid, f.d_min, f.d_max, 0.5)
                  .item<float>(),
              0.5 * 0.25 + 0.25, 1e-6);
  // Only pixel 0 valid: errors 0.5 and 0.
  const torch::Tensor first = torch::tensor({true, false}).view({1, 1, 1, 2});
  EXPECT_NEAR(SequenceLoss({f.pred0, f.pred1}, f.gt, first, f.d_min, f.d_max, 0.5).item<float>(),
              0.5 * 0.5, 1e-6);
  // The last iteration has weight 1 whatever gamma is.
  EXPECT_NEAR(SequenceLoss({f.pred1}, f.gt, all_valid, f.d_min, f.d_max, 0.1).item<float>(),
              0.25, 1e-6);
}

TEST(SequenceLossTest, NormalisationIsPerSampleAndNotClipped) {
  // Sample 1 has range [2, 4]: gt 4 -> norm 0; prediction 1.0 (depth 1, far
  // outside the range) -> norm (1 - 0.25) / 0.25 = 3, error 3 (not clipped to 1).
  const torch::Tensor gt = torch::tensor({1.0f, 4.0f}).view({2, 1, 1, 1});
  const torch::Tensor pred = torch::tensor({1.0f, 1.0f}).view({2, 1, 1, 1});
  const torch::Tensor d_min = torch::tensor({1.0f, 2.0f});
  const torch::Tensor d_max = torch::tensor({2.0f, 4.0f});
  const torch::Tensor valid = torch::ones({2, 1, 1, 1}, torch::kBool);
  EXPECT_NEAR(SequenceLoss({pred}, gt, valid, d_min, d_max).item<float>(), (0.0 + 3.0) / 2, 1e-5);
}

TEST(SequenceLossTest, GradientAndUnusableGroundTruth) {
  Fixture f;
  torch::Tensor pred = f.pred0.clone().requires_grad_(true);
  // Pixel 1 is marked valid but its depth is NaN: it must be ignored.
  const torch::Tensor gt = torch::tensor({1.0f, std::nanf("")}).view({1, 1, 1, 2});
  const torch::Tensor valid = torch::ones({1, 1, 1, 2}, torch::kBool);
  const torch::Tensor loss = SequenceLoss({pred}, gt, valid, f.d_min, f.d_max);
  EXPECT_NEAR(loss.item<float>(), 0.5, 1e-6);
  loss.backward();
  // d/dw |(w - 0.5)/0.5 - 1| at w = 0.75 (below target) = -2; one valid pixel.
  EXPECT_NEAR(pred.grad()[0][0][0][0].item<float>(), -2.0f, 1e-5);
  EXPECT_EQ(pred.grad()[0][0][0][1].item<float>(), 0.0f);
}

TEST(SequenceLossTest, NoValidPixelGivesZeroAndBackwardWorks) {
  Fixture f;
  torch::Tensor pred = f.pred0.clone().requires_grad_(true);
  const torch::Tensor none = torch::zeros({1, 1, 1, 2}, torch::kBool);
  const torch::Tensor loss = SequenceLoss({pred}, f.gt, none, f.d_min, f.d_max);
  EXPECT_EQ(loss.item<float>(), 0.0f);
  loss.backward();
  EXPECT_EQ(pred.grad().abs().sum().item<float>(), 0.0f);
}

TEST(SequenceLossTest, RejectsBadInput) {
  Fixture f;
  const torch::Tensor valid = torch::ones({1, 1, 1, 2}, torch::kBool);
  EXPECT_THROW(SequenceLoss({}, f.gt, valid, f.d_min, f.d_max), std::invalid_argument);
  EXPECT_THROW(SequenceLoss({f.pred0}, f.gt, valid, f.d_min, f.d_max, 0.0), std::invalid_argument);
  EXPECT_THROW(SequenceLoss({f.pred0}, f.gt, valid, f.d_min, f.d_max, 1.5), std::invalid_argument);
  EXPECT_THROW(SequenceLoss({torch::zeros({1, 1, 2, 2})}, f.gt, valid, f.d_min, f.d_max),
               std::invalid_argument);
  EXPECT_THROW(SequenceLoss({f.pred0}, f.gt, torch::ones({1, 1, 2, 1}), f.d_min, f.d_max),
               std::invalid_argument);
  EXPECT_THROW(SequenceLoss({f.pred0}, f.gt, valid, torch::tensor({1.0f, 1.0f}), f.d_max),
               std::invalid_argument);
}

// The log loss, computed here from std::log on the numbers, not by the
// function under test.
TEST(LogDepthSequenceLossTest, HandComputedValueAndWeights) {
  // Ground truth 2 and 8 (inverse 0.5, 0.125); predictions 10 % and 1 % far.
  const torch::Tensor gt = torch::tensor({2.0f, 8.0f}).view({1, 1, 1, 2});
  const torch::Tensor pred = torch::tensor({1.0f / 2.2f, 1.0f / 8.08f}).view({1, 1, 1, 2});
  const torch::Tensor exact = 1.0 / gt;
  const torch::Tensor valid = torch::ones({1, 1, 1, 2}, torch::kBool);
  const double per_iteration = (std::log(1.1) + std::log(1.01)) / 2;
  EXPECT_NEAR(LogDepthSequenceLoss({pred}, gt, valid).item<float>(), per_iteration, 1e-6);
  // Earlier iterations decay by gamma; an exact last iteration adds 0.
  EXPECT_NEAR(LogDepthSequenceLoss({pred, exact}, gt, valid, 0.5).item<float>(), 0.5 * per_iteration,
              1e-6);
}

TEST(LogDepthSequenceLossTest, WeighsTheSameRelativeErrorAlikeAtAnyDepth) {
  // 2 % too far at depth 0.2 and at depth 8.6: equal log terms, while the
  // paper's loss over the range [0.2, 8.6] weighs the far one 43 times less.
  const torch::Tensor gt = torch::tensor({0.2f, 8.6f}).view({1, 1, 1, 2});
  const torch::Tensor pred = 1.0 / (gt * 1.02);
  const torch::Tensor d_min = torch::tensor({0.2f});
  const torch::Tensor d_max = torch::tensor({8.6f});
  const torch::Tensor near_only = torch::tensor({true, false}).view({1, 1, 1, 2});
  const torch::Tensor far_only = torch::tensor({false, true}).view({1, 1, 1, 2});
  EXPECT_NEAR(LogDepthSequenceLoss({pred}, gt, near_only).item<float>(), std::log(1.02), 1e-6);
  EXPECT_NEAR(LogDepthSequenceLoss({pred}, gt, far_only).item<float>(), std::log(1.02), 1e-6);
  const double near_paper = SequenceLoss({pred}, gt, near_only, d_min, d_max).item<double>();
  const double far_paper = SequenceLoss({pred}, gt, far_only, d_min, d_max).item<double>();
  EXPECT_NEAR(near_paper / far_paper, 8.6 / 0.2, 0.01 * 8.6 / 0.2);
}

TEST(LogDepthSequenceLossTest, GradientCapAndUnusablePredictions) {
  // Pixel 0: depth 4 against 2, |log 2| < cap, d/dw |log(w * gt)| = sign / w.
  // Pixel 1: 10x too near, beyond the cap: the cap, no gradient.
  // Pixel 2: no triangulation (0): the cap, no gradient.
  // Pixel 3: NaN prediction: the cap, no gradient, nothing NaN.
  const torch::Tensor gt = torch::tensor({2.0f, 2.0f, 2.0f, 2.0f}).view({1, 1, 1, 4});
  torch::Tensor pred = torch::tensor({0.25f, 5.0f, 0.0f, std::nanf("")}).view({1, 1, 1, 4});
  pred.requires_grad_(true);
  const torch::Tensor valid = torch::ones({1, 1, 1, 4}, torch::kBool);
  const torch::Tensor loss = LogDepthSequenceLoss({pred}, gt, valid);
  EXPECT_NEAR(loss.item<float>(), (std::log(2.0) + 3 * kLogLossCap) / 4, 1e-6);
  loss.backward();
  const torch::Tensor grad = pred.grad().flatten();
  EXPECT_NEAR(grad[0].item<float>(), -1.0 / 0.25 / 4, 1e-5);
  for (int i = 1; i < 4; ++i) EXPECT_EQ(grad[i].item<float>(), 0.0f) << i;
}

TEST(LogDepthSequenceLossTest, NoValidPixelAndBadInput) {
  const torch::Tensor gt = torch::tensor({2.0f, std::nanf("")}).view({1, 1, 1, 2});
  torch::Tensor pred = torch::tensor({1.0f, 1.0f}).view({1, 1, 1, 2}).requires_grad_(true);
  // Pixel 0 masked out, pixel 1 has unusable ground truth.
  const torch::Tensor valid = torch::tensor({false, true}).view({1, 1, 1, 2});
  const torch::Tensor loss = LogDepthSequenceLoss({pred}, gt, valid);
  EXPECT_EQ(loss.item<float>(), 0.0f);
  loss.backward();
  EXPECT_EQ(pred.grad().abs().sum().item<float>(), 0.0f);
  EXPECT_THROW(LogDepthSequenceLoss({}, gt, valid), std::invalid_argument);
  EXPECT_THROW(LogDepthSequenceLoss({pred}, gt, valid, 0.0), std::invalid_argument);
  EXPECT_THROW(LogDepthSequenceLoss({torch::zeros({1, 1, 2, 2})}, gt, valid), std::invalid_argument);
}

TEST(DepthLossNameTest, RoundTripAndRejects) {
  for (DepthLoss loss : {DepthLoss::kNormalizedInverse, DepthLoss::kLog}) {
    EXPECT_EQ(ParseDepthLoss(DepthLossName(loss)), loss);
  }
  EXPECT_THROW(ParseDepthLoss("l1"), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
