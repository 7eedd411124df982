#include "train/validation_metrics.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace dispmvs::train {
namespace {

torch::Tensor Map(std::vector<double> values) {
  return torch::tensor(values, torch::kDouble).reshape({1, 1, 2, 3});
}

// gt: five valid pixels at depth 10, one without ground truth.
// pred: errors 0.5 %, 1.5 %, 4 %, 10 %, one missing prediction, and one
// prediction where there is no ground truth (ignored).
TEST(ValidationDepthMetricsTest, HandComputedFractionsAbsRelAndCoverage) {
  const auto gt = Map({10, 10, 10, 10, 10, 0});
  const auto pred = Map({10.05, 10.15, 10.4, 11, 0, 5});
  const auto pred_valid = Map({1, 1, 1, 1, 0, 1}).to(torch::kBool);
  const auto m = FinalizeValidation(SumValidationDepth(pred, pred_valid, gt, gt > 0));
  EXPECT_EQ(m.gt_pixels, 5);
  EXPECT_DOUBLE_EQ(m.within_1, 1.0 / 5);
  EXPECT_DOUBLE_EQ(m.within_2, 2.0 / 5);
  EXPECT_DOUBLE_EQ(m.within_5, 3.0 / 5);
  EXPECT_DOUBLE_EQ(m.coverage, 4.0 / 5);
  // The missing prediction counts as relative error 1.
  EXPECT_NEAR(m.abs_rel, (0.005 + 0.015 + 0.04 + 0.1 + 1.0) / 5, 1e-12);
}

TEST(ValidationDepthMetricsTest, NonFiniteOrNonPositivePredictionIsMissing) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const auto gt = Map({4, 4, 4, 4, 4, 4});
  const auto pred = Map({4, nan, -4, 0, 4.1, 4});  // 4.1: 2.5 % off
  const auto all_valid = torch::ones({1, 1, 2, 3}, torch::kBool);
  const auto m = FinalizeValidation(SumValidationDepth(pred, all_valid, gt, all_valid));
  EXPECT_EQ(m.gt_pixels, 6);
  EXPECT_DOUBLE_EQ(m.coverage, 3.0 / 6);
  EXPECT_DOUBLE_EQ(m.within_1, 2.0 / 6);
  EXPECT_DOUBLE_EQ(m.within_2, 2.0 / 6);
  EXPECT_DOUBLE_EQ(m.within_5, 3.0 / 6);
  EXPECT_NEAR(m.abs_rel, (0 + 1 + 1 + 1 + 0.025 + 0) / 6.0, 1e-12);
}

TEST(ValidationDepthMetricsTest, SumsOfBatchesAddUpPixelWeighted) {
  // Batch A: 1 pixel exact; batch B: 3 pixels, all missing.
  const auto one = torch::ones({1, 1, 1, 1}, torch::kDouble);
  ValidationDepthSums sums = SumValidationDepth(one, one > 0, one, one > 0);
  const auto three = torch::full({1, 1, 1, 3}, 2.0, torch::kDouble);
  sums += SumValidationDepth(three, three < 0, three, three > 0);
  const auto m = FinalizeValidation(sums);
  EXPECT_EQ(m.gt_pixels, 4);
  EXPECT_DOUBLE_EQ(m.within_1, 0.25);
  EXPECT_DOUBLE_EQ(m.coverage, 0.25);
  EXPECT_DOUBLE_EQ(m.abs_rel, 0.75);
}

TEST(ValidationDepthMetricsTest, NoGroundTruthGivesZerosAndBadShapesThrow) {
  const auto zeros = torch::zeros({1, 1, 2, 2});
  const auto m = FinalizeValidation(SumValidationDepth(zeros, zeros > 0, zeros, zeros > 0));
  EXPECT_EQ(m.gt_pixels, 0);
  EXPECT_EQ(m.abs_rel, 0);
  EXPECT_THROW(SumValidationDepth(torch::zeros({1, 1, 2, 3}), zeros > 0, zeros, zeros > 0),
               std::invalid_argument);
  EXPECT_THROW(SumValidationDepth(zeros, torch::Tensor(), zeros, zeros > 0), std::invalid_argument);
  EXPECT_THROW(SumValidationDepth(zeros.squeeze(1), zeros.squeeze(1) > 0, zeros.squeeze(1),
                               zeros.squeeze(1) > 0),
               std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::train
