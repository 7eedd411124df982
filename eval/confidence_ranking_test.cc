#include "eval/confidence_ranking.h"

#include <cmath>

#include <gtest/gtest.h>

#include "eval/depth_metrics.h"

namespace dispmvs::eval {
namespace {

colmap_io::DenseArray Map(int width, int height, const std::vector<float>& values) {
  colmap_io::DenseArray map(width, height, 1);
  std::copy(values.begin(), values.end(), map.data());
  return map;
}

// The ranking of `depth` against `gt`, from the relative errors the depth
// metrics compute, as dispmvs_eval ranks a map.
ConfidenceRankingSums Rank(const colmap_io::DenseArray& depth, const colmap_io::DenseArray& confidence,
                           const colmap_io::DenseArray& gt) {
  cv::Mat rel_error;
  SumDepthMetrics(depth, gt, &rel_error);
  return SumConfidenceRanking(rel_error, confidence);
}

TEST(ConfidenceRankingTest, MostConfidentPixelsComeFirst) {
  // Four pixels with ground truth 10: errors 0.5 %, 10 %, 1 %, 30 %; one
  // without a prediction and one without ground truth (neither counted).
  const auto gt = Map(3, 2, {10, 10, 10, 10, 10, 0});
  const auto depth = Map(3, 2, {10.05f, 11, 9.9f, 13, 0, 5});
  const auto confidence = Map(3, 2, {0.9f, 0.2f, 0.7f, 0.1f, 1.0f, 1.0f});
  const ConfidenceRankingSums sums = Rank(depth, confidence, gt);
  EXPECT_EQ(sums.total(), 4);
  EXPECT_DOUBLE_EQ(sums.ShareWithin2AtCoverage(0.5), 1.0);
  EXPECT_DOUBLE_EQ(sums.ShareWithin2AtCoverage(0.75), 2.0 / 3);
  EXPECT_DOUBLE_EQ(sums.ShareWithin2AtCoverage(1.0), 0.5);
  // At full coverage the share is the depth metrics' within 2 % of the predicted.
  const DepthMetrics metrics = Finalize(SumDepthMetrics(depth, gt));
  EXPECT_DOUBLE_EQ(sums.ShareWithin2AtCoverage(1.0), metrics.within_2_of_predicted);
  // A coverage ending inside a bin counts it pro rata: 0.375 of 4 pixels is
  // the best pixel and half of the second.
  EXPECT_DOUBLE_EQ(sums.ShareWithin2AtCoverage(0.375), 1.0);

  // Reversed confidence: the wrong pixels first.
  const auto reversed = Map(3, 2, {0.1f, 0.7f, 0.2f, 0.9f, 0, 0});
  EXPECT_DOUBLE_EQ(Rank(depth, reversed, gt).ShareWithin2AtCoverage(0.5), 0.0);
}

TEST(ConfidenceRankingTest, SumsAddAcrossViewsAndBadInputIsRefused) {
  const auto gt = Map(2, 1, {10, 10});
  const auto depth = Map(2, 1, {10, 12});
  ConfidenceRankingSums total;
  EXPECT_TRUE(std::isnan(total.ShareWithin2AtCoverage(1.0)));
  total += Rank(depth, Map(2, 1, {0.6f, 0.4f}), gt);
  total += Rank(depth, Map(2, 1, {0.8f, std::nanf("")}), gt);  // NaN counts as 0
  EXPECT_EQ(total.total(), 4);
  EXPECT_DOUBLE_EQ(total.ShareWithin2AtCoverage(0.5), 1.0);
  EXPECT_DOUBLE_EQ(total.ShareWithin2AtCoverage(1.0), 0.5);
  EXPECT_THROW(total.ShareWithin2AtCoverage(0.0), std::invalid_argument);
  EXPECT_THROW(total.ShareWithin2AtCoverage(1.5), std::invalid_argument);
  EXPECT_THROW(Rank(depth, Map(1, 1, {0.5f}), gt), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::eval
