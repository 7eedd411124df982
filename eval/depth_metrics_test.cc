#include "eval/depth_metrics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

namespace dispmvs::eval {
namespace {

using colmap_io::DenseArray;

// A 1-channel map from rows of values.
DenseArray Map(const std::vector<std::vector<float>>& rows) {
  DenseArray map(static_cast<int>(rows[0].size()), static_cast<int>(rows.size()), 1);
  for (std::size_t r = 0; r < rows.size(); ++r) {
    for (std::size_t c = 0; c < rows[r].size(); ++c) {
      map.at(static_cast<int>(r), static_cast<int>(c)) = rows[r][c];
    }
  }
  return map;
}

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

TEST(EvalDepthMetricsTest, HandComputedNumbers) {
  // GT-valid pixels: 1, 2, 4, 5, 10, 2 (six). Predictions:
  //   1.005 vs 1  -> rel 0.005      2.03 vs 2 -> 0.015
  //   0 vs 4      -> missing        3 vs 0 (no GT) -> not scored
  //   5.5 vs 5    -> 0.1            NaN vs 10 -> missing
  //   0 vs 0      -> nothing        2.08 vs 2 -> 0.04
  const DenseArray gt = Map({{1, 2, 4, 0}, {5, 10, 0, 2}});
  const DenseArray pred = Map({{1.005f, 2.03f, 0, 3}, {5.5f, kNaN, 0, 2.08f}});
  const DepthMetricSums sums = SumDepthMetrics(pred, gt);
  EXPECT_EQ(sums.gt_pixels, 6);
  EXPECT_EQ(sums.predicted, 4);
  EXPECT_EQ(sums.predicted_without_gt, 1);
  EXPECT_EQ(sums.within_1, 1);
  EXPECT_EQ(sums.within_2, 2);
  EXPECT_EQ(sums.within_5, 3);

  const DepthMetrics m = Finalize(sums);
  EXPECT_DOUBLE_EQ(m.coverage, 4.0 / 6.0);
  EXPECT_NEAR(m.abs_rel, (0.005 + 0.015 + 0.1 + 0.04) / 4, 1e-6);
  EXPECT_DOUBLE_EQ(m.within_1_of_predicted, 0.25);
  EXPECT_DOUBLE_EQ(m.within_2_of_predicted, 0.5);
  EXPECT_DOUBLE_EQ(m.within_5_of_predicted, 0.75);
  EXPECT_DOUBLE_EQ(m.within_1_of_gt, 1.0 / 6.0);
  EXPECT_DOUBLE_EQ(m.within_2_of_gt, 2.0 / 6.0);
  EXPECT_DOUBLE_EQ(m.within_5_of_gt, 3.0 / 6.0);
  // Median of {0.005, 0.015, 0.04, 0.1}: (0.015 + 0.04) / 2, histogram precision.
  EXPECT_NEAR(m.median_rel, 0.0275, 0.0275 * 1e-3);
}

TEST(EvalDepthMetricsTest, NonFiniteAndNegativePredictionsAreMissing) {
  const DenseArray gt = Map({{1, 1, 1, 1}});
  const DenseArray pred = Map({{kNaN, kInf, -1, 1}});
  cv::Mat rel;
  const DepthMetrics m = Finalize(SumDepthMetrics(pred, gt, &rel));
  EXPECT_EQ(m.gt_pixels, 4);
  EXPECT_EQ(m.predicted, 1);
  EXPECT_DOUBLE_EQ(m.coverage, 0.25);
  EXPECT_DOUBLE_EQ(m.abs_rel, 0.0);
  EXPECT_DOUBLE_EQ(m.median_rel, 0.0);
  ASSERT_EQ(rel.type(), CV_32FC1);
  EXPECT_EQ(rel.at<float>(0, 0), kRelErrorMissing);
  EXPECT_EQ(rel.at<float>(0, 2), kRelErrorMissing);
  EXPECT_EQ(rel.at<float>(0, 3), 0.0f);
  // Non-finite GT is no surface.
  const DepthMetrics none = Finalize(SumDepthMetrics(Map({{1}}), Map({{kInf}})));
  EXPECT_EQ(none.gt_pixels, 0);
  EXPECT_EQ(none.predicted_without_gt, 1);
  EXPECT_TRUE(std::isnan(none.coverage));
  EXPECT_TRUE(std::isnan(none.abs_rel));
  EXPECT_TRUE(std::isnan(none.median_rel));
}

TEST(EvalDepthMetricsTest, OverallNumbersArePixelWeighted) {
  // View A: 1 GT pixel, predicted with rel 0.005. View B: 3 GT pixels, one
  // predicted with rel 0.1.
  DepthMetricSums a = SumDepthMetrics(Map({{1.005f}}), Map({{1}}));
  const DepthMetricSums b = SumDepthMetrics(Map({{1.1f, 0, 0}}), Map({{1, 2, 3}}));
  a += b;
  const DepthMetrics m = Finalize(a);
  EXPECT_EQ(m.gt_pixels, 4);
  EXPECT_EQ(m.predicted, 2);
  EXPECT_DOUBLE_EQ(m.coverage, 0.5);
  EXPECT_NEAR(m.abs_rel, (0.005 + 0.1) / 2, 1e-6);
  EXPECT_DOUBLE_EQ(m.within_1_of_predicted, 0.5);
  EXPECT_DOUBLE_EQ(m.within_1_of_gt, 0.25);
  EXPECT_NEAR(m.median_rel, 0.0525, 0.0525 * 1e-3);
}

TEST(EvalDepthMetricsTest, SmallerMapSamplesTheGtAtTheSamePosition) {
  // GT 4x4 with distinct depths; a 2x2 map (s = 1/2) pixel (col, row) sits at
  // image position (2 col, 2 row): raw indices, no half-pixel shift.
  DenseArray gt(4, 4, 1);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) gt.at(r, c) = 1.0f + 4.0f * r + c;
  }
  DenseArray pred(2, 2, 1);
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 2; ++c) pred.at(r, c) = gt.at(2 * r, 2 * c);
  }
  cv::Mat rel;
  DepthMetrics m = Finalize(SumDepthMetrics(pred, gt, &rel));
  EXPECT_EQ(m.gt_pixels, 4);
  EXPECT_DOUBLE_EQ(m.coverage, 1.0);
  EXPECT_DOUBLE_EQ(m.abs_rel, 0.0);
  EXPECT_EQ(rel.rows, 2);
  EXPECT_EQ(rel.cols, 2);
  // A map sampled half a pixel further (at 2 col + 1) is off.
  pred.at(1, 1) = gt.at(3, 3);  // 16 vs the GT's 11 at (2, 2)
  m = Finalize(SumDepthMetrics(pred, gt));
  EXPECT_NEAR(m.abs_rel, (16.0 - 11.0) / 11.0 / 4, 1e-6);
}

TEST(EvalDepthMetricsTest, NearestGtIndexRoundsHalvesUpAndClamps) {
  EXPECT_EQ(NearestGtIndex(0, 3, 5), 0);
  EXPECT_EQ(NearestGtIndex(1, 3, 5), 2);  // 1.667
  EXPECT_EQ(NearestGtIndex(2, 3, 5), 3);  // 3.333
  EXPECT_EQ(NearestGtIndex(1, 2, 3), 2);  // 1.5 -> 2
  EXPECT_EQ(NearestGtIndex(3, 4, 8), 6);
  EXPECT_EQ(NearestGtIndex(7, 8, 8), 7);
  EXPECT_EQ(NearestGtIndex(2, 3, 4), 3);  // 2.667
  EXPECT_EQ(NearestGtIndex(5, 6, 7), 6);  // 5.833, within range
}

TEST(EvalDepthMetricsTest, CleanScales) {
  EXPECT_TRUE(IsCleanScale(8, 6, 8, 6));
  EXPECT_TRUE(IsCleanScale(4, 3, 8, 6));
  EXPECT_TRUE(IsCleanScale(1000, 750, 1600, 1200));  // max_image_size 1000
  EXPECT_TRUE(IsCleanScale(3, 2, 5, 3));             // s = 0.6: 3, 1.8 -> 2
  EXPECT_FALSE(IsCleanScale(1000, 751, 1600, 1200));
  EXPECT_FALSE(IsCleanScale(4, 4, 8, 6));
  EXPECT_FALSE(IsCleanScale(9, 6, 8, 6));  // larger than the GT
  EXPECT_FALSE(IsCleanScale(8, 5, 8, 6));
  EXPECT_FALSE(IsCleanScale(0, 0, 8, 6));
}

TEST(EvalDepthMetricsTest, RejectsBadSizesAndChannels) {
  const DenseArray gt(8, 6, 1, 1.0f);
  EXPECT_THROW(SumDepthMetrics(DenseArray(6, 3, 1, 1.0f), gt), std::invalid_argument);
  EXPECT_THROW(SumDepthMetrics(DenseArray(16, 12, 1, 1.0f), gt), std::invalid_argument);
  EXPECT_THROW(SumDepthMetrics(DenseArray(8, 6, 3, 1.0f), gt), std::invalid_argument);
  EXPECT_THROW(SumDepthMetrics(DenseArray(), gt), std::invalid_argument);
  EXPECT_NO_THROW(SumDepthMetrics(DenseArray(4, 3, 1, 1.0f), gt));
}

TEST(EvalRelErrorHistogramTest, Median) {
  RelErrorHistogram h;
  EXPECT_TRUE(std::isnan(h.Median()));
  h.Add(0.015);
  EXPECT_DOUBLE_EQ(h.Median(), 0.015);  // alone in its bin: exact
  h.Add(0.0);
  h.Add(0.0);
  EXPECT_EQ(h.Median(), 0.0);
  h.Add(5000.0);
  // {0, 0, 0.015, 5000}: (0 + 0.015) / 2.
  EXPECT_DOUBLE_EQ(h.Median(), 0.0075);
  RelErrorHistogram other;
  for (int i = 1; i <= 999; ++i) other.Add(i * 1e-4);  // median 0.05
  EXPECT_NEAR(other.Median(), 0.05, 1e-15);
  other += h;  // 1003 values: the 502nd smallest, 0.0499
  EXPECT_EQ(other.count(), 1003);
  EXPECT_NEAR(other.Median(), 0.0499, 1e-15);
}

TEST(EvalRelErrorHistogramTest, MedianWithinItsBin) {
  // 0.05007 and 0.05009 share a bin (width 0.115 %): the median (0.05009) comes
  // back as the bin's mean, within one bin width.
  RelErrorHistogram h;
  h.Add(0.05007);
  h.Add(0.05009);
  h.Add(0.05009);
  EXPECT_NEAR(h.Median(), (0.05007 + 2 * 0.05009) / 3, 1e-15);
  EXPECT_NEAR(h.Median(), 0.05009, 0.05009 * 1.2e-3);
}

// Disparity of depth z for f B = kFocalBaseline, and the depth of a disparity.
constexpr double kFocalBaseline = 16.0;  // e.g. f = 8 px, B = 2
float DepthOfDisparity(double disparity) { return static_cast<float>(kFocalBaseline / disparity); }

TEST(EvalDisparityMetricsTest, KnownDisparityShifts) {
  // GT: a fronto-parallel plane at z = 4, disparity 16 / 4 = 4 px. The
  // predictions shift the disparity by +0.5, -1.5, +3 and -0.999 px; one GT
  // pixel has no prediction and one prediction has no GT.
  const float z = 4.0f;
  const DenseArray gt = Map({{z, z, z, z}, {z, z, z, 0}});
  const DenseArray pred = Map({{DepthOfDisparity(4.5), DepthOfDisparity(2.5), DepthOfDisparity(7.0),
                                DepthOfDisparity(3.001)},
                               {0, z, kNaN, 2.0f}});
  const DisparityMetricSums sums = SumDisparityMetrics(pred, gt, kFocalBaseline);
  EXPECT_EQ(sums.views, 1);
  EXPECT_EQ(sums.gt_pixels, 7);
  EXPECT_EQ(sums.predicted, 5);
  EXPECT_EQ(sums.within_1px, 3);  // 0.5, 0.999 and 0
  EXPECT_EQ(sums.within_2px, 4);  // and 1.5
  EXPECT_NEAR(sums.error_sum, 0.5 + 1.5 + 3.0 + 0.999 + 0.0, 1e-5);

  const DisparityMetrics m = Finalize(sums);
  EXPECT_TRUE(m.applicable);
  EXPECT_EQ(m.gt_pixels, 7);
  EXPECT_EQ(m.predicted, 5);
  EXPECT_NEAR(m.mean_error, 5.999 / 5, 1e-6);
  EXPECT_DOUBLE_EQ(m.within_1px_of_predicted, 3.0 / 5);
  EXPECT_DOUBLE_EQ(m.within_2px_of_predicted, 4.0 / 5);
  EXPECT_DOUBLE_EQ(m.within_1px_of_gt, 3.0 / 7);
  EXPECT_DOUBLE_EQ(m.within_2px_of_gt, 4.0 / 7);

  // Same depths, three times the baseline: every disparity error triples, to
  // 1.5, 4.5, 9, 2.997 and 0 px.
  const DisparityMetricSums tripled = SumDisparityMetrics(pred, gt, 3 * kFocalBaseline);
  EXPECT_NEAR(tripled.error_sum, 3 * sums.error_sum, 1e-5);
  EXPECT_EQ(tripled.within_1px, 1);
  EXPECT_EQ(tripled.within_2px, 2);
}

TEST(EvalDisparityMetricsTest, SlantedPlaneAndSmallerMap) {
  // GT 8x4: disparity 2 + 0.25 col (a slanted plane); a 4x2 map compares
  // map pixel (c, r) with GT pixel (2c, 2r). Its depths carry a 1.5 px error
  // at the GT's resolution: the focal length passed in decides the unit.
  DenseArray gt(8, 4, 1);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 8; ++c) gt.at(r, c) = DepthOfDisparity(2.0 + 0.25 * c);
  }
  DenseArray pred(4, 2, 1);
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 4; ++c) pred.at(r, c) = DepthOfDisparity(2.0 + 0.25 * (2 * c) + 1.5);
  }
  const DisparityMetrics m = Finalize(SumDisparityMetrics(pred, gt, kFocalBaseline));
  EXPECT_EQ(m.gt_pixels, 8);
  EXPECT_EQ(m.predicted, 8);
  EXPECT_NEAR(m.mean_error, 1.5, 1e-5);
  EXPECT_EQ(m.within_1px_of_gt, 0.0);
  EXPECT_EQ(m.within_2px_of_gt, 1.0);
}

TEST(EvalDisparityMetricsTest, SumsAddUpAndNotApplicableIsNaN) {
  const DenseArray gt = Map({{4, 4}});
  DisparityMetricSums a = SumDisparityMetrics(Map({{DepthOfDisparity(4.5), 0}}), gt, kFocalBaseline);
  const DisparityMetricSums b = SumDisparityMetrics(Map({{DepthOfDisparity(7.0), 4}}), gt,
                                                    kFocalBaseline);
  a += b;
  EXPECT_EQ(a.views, 2);
  const DisparityMetrics m = Finalize(a);
  EXPECT_EQ(m.gt_pixels, 4);
  EXPECT_EQ(m.predicted, 3);
  EXPECT_NEAR(m.mean_error, (0.5 + 3.0 + 0.0) / 3, 1e-6);
  EXPECT_DOUBLE_EQ(m.within_1px_of_gt, 0.5);
  EXPECT_DOUBLE_EQ(m.within_2px_of_predicted, 2.0 / 3);

  // No view with a partner: not applicable, every number NaN.
  const DisparityMetrics none = Finalize(DisparityMetricSums{});
  EXPECT_FALSE(none.applicable);
  EXPECT_EQ(none.gt_pixels, 0);
  EXPECT_TRUE(std::isnan(none.mean_error));
  EXPECT_TRUE(std::isnan(none.within_1px_of_gt));
  EXPECT_TRUE(std::isnan(none.within_2px_of_predicted));
  // A view with a partner but no prediction: applicable, fractions of GT 0.
  const DisparityMetrics empty = Finalize(SumDisparityMetrics(Map({{0, 0}}), gt, kFocalBaseline));
  EXPECT_TRUE(empty.applicable);
  EXPECT_EQ(empty.within_1px_of_gt, 0.0);
  EXPECT_TRUE(std::isnan(empty.mean_error));
}

TEST(EvalDisparityMetricsTest, RejectsBadInput) {
  const DenseArray gt(8, 6, 1, 1.0f);
  EXPECT_THROW(SumDisparityMetrics(DenseArray(6, 3, 1, 1.0f), gt, 1.0), std::invalid_argument);
  EXPECT_THROW(SumDisparityMetrics(DenseArray(8, 6, 1, 1.0f), gt, 0.0), std::invalid_argument);
  EXPECT_THROW(SumDisparityMetrics(DenseArray(8, 6, 1, 1.0f), gt, -2.0), std::invalid_argument);
  EXPECT_THROW(SumDisparityMetrics(DenseArray(8, 6, 1, 1.0f), gt, kNaN), std::invalid_argument);
  EXPECT_NO_THROW(SumDisparityMetrics(DenseArray(4, 3, 1, 1.0f), gt, 1.0));
}

}  // namespace
}  // namespace dispmvs::eval
