#include "eval/depth_metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace dispmvs::eval {
namespace {

constexpr int kNumLogBins = RelErrorHistogram::kBinsPerDecade * RelErrorHistogram::kNumDecades;
// Layout: [0] below kMinError, [1, kNumLogBins] log bins, [kNumLogBins + 1] from kMaxError.
constexpr int kNumBins = kNumLogBins + 2;

bool ValidDepth(float depth) { return std::isfinite(depth) && depth > 0.0f; }

std::string SizeText(int width, int height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

// The checks both scorers make before matching pixels.
void CheckComparable(const colmap_io::DenseArray& prediction, const colmap_io::DenseArray& gt) {
  if (prediction.empty() || gt.empty()) {
    throw std::invalid_argument("depth map or ground truth is empty");
  }
  if (prediction.channels() != 1 || gt.channels() != 1) {
    throw std::invalid_argument("depth maps must have 1 channel (prediction has " +
                                std::to_string(prediction.channels()) + ", ground truth " +
                                std::to_string(gt.channels()) + ")");
  }
  const int width = prediction.width();
  const int height = prediction.height();
  if (!IsCleanScale(width, height, gt.width(), gt.height())) {
    throw std::invalid_argument("depth map is " + SizeText(width, height) +
                                " but its ground truth is " + SizeText(gt.width(), gt.height()) +
                                ": not the same size nor a down-scale of it by one factor");
  }
}

}  // namespace

void RelErrorHistogram::Add(double rel_error) {
  if (bins_.empty()) {
    bins_.assign(kNumBins, 0);
    sums_.assign(kNumBins, 0.0);
  }
  int bin;
  if (!(rel_error >= kMinError)) {  // also NaN, which callers never pass
    bin = 0;
  } else if (rel_error >= kMaxError) {
    bin = kNumBins - 1;
  } else {
    const double position = (std::log10(rel_error) - std::log10(kMinError)) * kBinsPerDecade;
    bin = 1 + std::clamp(static_cast<int>(std::floor(position)), 0, kNumLogBins - 1);
  }
  ++bins_[bin];
  sums_[bin] += rel_error;
  ++count_;
}

RelErrorHistogram& RelErrorHistogram::operator+=(const RelErrorHistogram& other) {
  if (other.bins_.empty()) return *this;
  if (bins_.empty()) {
    bins_.assign(kNumBins, 0);
    sums_.assign(kNumBins, 0.0);
  }
  for (int i = 0; i < kNumBins; ++i) {
    bins_[i] += other.bins_[i];
    sums_[i] += other.sums_[i];
  }
  count_ += other.count_;
  return *this;
}

double RelErrorHistogram::ValueAtRank(int64_t rank) const {
  int64_t seen = 0;
  for (int bin = 0; bin < kNumBins; ++bin) {
    seen += bins_[bin];
    if (seen > rank) return sums_[bin] / static_cast<double>(bins_[bin]);
  }
  return kMaxError;  // unreachable: rank < count_
}

double RelErrorHistogram::Median() const {
  if (count_ == 0) return std::numeric_limits<double>::quiet_NaN();
  const int64_t low = (count_ - 1) / 2;
  const int64_t high = count_ / 2;
  if (low == high) return ValueAtRank(low);
  return 0.5 * (ValueAtRank(low) + ValueAtRank(high));
}

DepthMetricSums& DepthMetricSums::operator+=(const DepthMetricSums& other) {
  gt_pixels += other.gt_pixels;
  predicted += other.predicted;
  predicted_without_gt += other.predicted_without_gt;
  within_1 += other.within_1;
  within_2 += other.within_2;
  within_5 += other.within_5;
  abs_rel_sum += other.abs_rel_sum;
  rel_errors += other.rel_errors;
  return *this;
}

DepthMetrics Finalize(const DepthMetricSums& sums) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  DepthMetrics m;
  m.gt_pixels = sums.gt_pixels;
  m.predicted = sums.predicted;
  m.predicted_without_gt = sums.predicted_without_gt;
  const double gt = static_cast<double>(sums.gt_pixels);
  const double pred = static_cast<double>(sums.predicted);
  m.coverage = gt > 0 ? pred / gt : nan;
  m.within_1_of_gt = gt > 0 ? sums.within_1 / gt : nan;
  m.within_2_of_gt = gt > 0 ? sums.within_2 / gt : nan;
  m.within_5_of_gt = gt > 0 ? sums.within_5 / gt : nan;
  m.abs_rel = pred > 0 ? sums.abs_rel_sum / pred : nan;
  m.within_1_of_predicted = pred > 0 ? sums.within_1 / pred : nan;
  m.within_2_of_predicted = pred > 0 ? sums.within_2 / pred : nan;
  m.within_5_of_predicted = pred > 0 ? sums.within_5 / pred : nan;
  m.median_rel = sums.rel_errors.Median();
  return m;
}

bool IsCleanScale(int map_width, int map_height, int gt_width, int gt_height) {
  if (map_width < 1 || map_height < 1 || gt_width < 1 || gt_height < 1) return false;
  if (map_width > gt_width || map_height > gt_height) return false;
  if (map_width == gt_width && map_height == gt_height) return true;
  // Intervals of s allowed by each side; clean when they overlap.
  constexpr double kTolerance = 1e-2;  // pixels: COLMAP sizes come from float arithmetic
  const double low = std::max((map_width - 0.5 - kTolerance) / gt_width,
                              (map_height - 0.5 - kTolerance) / gt_height);
  const double high = std::min((map_width + 0.5 + kTolerance) / gt_width,
                               (map_height + 0.5 + kTolerance) / gt_height);
  return low <= high;
}

int NearestGtIndex(int index, int map_size, int gt_size) {
  // round(index * gt_size / map_size), halves up, in exact integer arithmetic:
  // floor((2 * index * gt_size + map_size) / (2 * map_size)).
  const int64_t numerator = 2 * static_cast<int64_t>(index) * gt_size + map_size;
  const int64_t nearest = numerator / (2 * static_cast<int64_t>(map_size));
  return static_cast<int>(std::clamp<int64_t>(nearest, 0, gt_size - 1));
}

DepthMetricSums SumDepthMetrics(const colmap_io::DenseArray& prediction,
                                const colmap_io::DenseArray& gt, cv::Mat* rel_error) {
  CheckComparable(prediction, gt);
  const int width = prediction.width();
  const int height = prediction.height();
  std::vector<int> gt_cols(width);
  for (int col = 0; col < width; ++col) gt_cols[col] = NearestGtIndex(col, width, gt.width());

  if (rel_error != nullptr) rel_error->create(height, width, CV_32FC1);
  DepthMetricSums sums;
  const float* pred_values = prediction.data();
  const float* gt_values = gt.data();
  for (int row = 0; row < height; ++row) {
    const int gt_row = NearestGtIndex(row, height, gt.height());
    const float* gt_line = gt_values + static_cast<std::size_t>(gt_row) * gt.width();
    const float* pred_line = pred_values + static_cast<std::size_t>(row) * width;
    float* error_line = rel_error != nullptr ? rel_error->ptr<float>(row) : nullptr;
    for (int col = 0; col < width; ++col) {
      const float g = gt_line[gt_cols[col]];
      const float d = pred_line[col];
      float code;
      if (!ValidDepth(g)) {
        if (ValidDepth(d)) ++sums.predicted_without_gt;
        code = kRelErrorNoGt;
      } else if (!ValidDepth(d)) {
        ++sums.gt_pixels;
        code = kRelErrorMissing;
      } else {
        ++sums.gt_pixels;
        ++sums.predicted;
        const double rel = std::abs(static_cast<double>(d) - g) / g;
        sums.abs_rel_sum += rel;
        if (rel < 0.01) ++sums.within_1;
        if (rel < 0.02) ++sums.within_2;
        if (rel < 0.05) ++sums.within_5;
        sums.rel_errors.Add(rel);
        code = static_cast<float>(rel);
      }
      if (error_line != nullptr) error_line[col] = code;
    }
  }
  return sums;
}

DisparityMetricSums& DisparityMetricSums::operator+=(const DisparityMetricSums& other) {
  views += other.views;
  gt_pixels += other.gt_pixels;
  predicted += other.predicted;
  within_1px += other.within_1px;
  within_2px += other.within_2px;
  error_sum += other.error_sum;
  return *this;
}

DisparityMetrics Finalize(const DisparityMetricSums& sums) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  DisparityMetrics m;
  m.applicable = sums.views > 0;
  if (!m.applicable) {
    m.mean_error = m.within_1px_of_predicted = m.within_2px_of_predicted = nan;
    m.within_1px_of_gt = m.within_2px_of_gt = nan;
    return m;
  }
  m.gt_pixels = sums.gt_pixels;
  m.predicted = sums.predicted;
  const double gt = static_cast<double>(sums.gt_pixels);
  const double pred = static_cast<double>(sums.predicted);
  m.mean_error = pred > 0 ? sums.error_sum / pred : nan;
  m.within_1px_of_predicted = pred > 0 ? sums.within_1px / pred : nan;
  m.within_2px_of_predicted = pred > 0 ? sums.within_2px / pred : nan;
  m.within_1px_of_gt = gt > 0 ? sums.within_1px / gt : nan;
  m.within_2px_of_gt = gt > 0 ? sums.within_2px / gt : nan;
  return m;
}

DisparityMetricSums SumDisparityMetrics(const colmap_io::DenseArray& prediction,
                                        const colmap_io::DenseArray& gt, double focal_baseline) {
  if (!(std::isfinite(focal_baseline) && focal_baseline > 0)) {
    throw std::invalid_argument("focal length x baseline must be finite and > 0, not " +
                                std::to_string(focal_baseline));
  }
  CheckComparable(prediction, gt);
  const int width = prediction.width();
  const int height = prediction.height();
  std::vector<int> gt_cols(width);
  for (int col = 0; col < width; ++col) gt_cols[col] = NearestGtIndex(col, width, gt.width());

  DisparityMetricSums sums;
  sums.views = 1;
  for (int row = 0; row < height; ++row) {
    const int gt_row = NearestGtIndex(row, height, gt.height());
    const float* gt_line = gt.data() + static_cast<std::size_t>(gt_row) * gt.width();
    const float* pred_line = prediction.data() + static_cast<std::size_t>(row) * width;
    for (int col = 0; col < width; ++col) {
      const float g = gt_line[gt_cols[col]];
      if (!ValidDepth(g)) continue;
      ++sums.gt_pixels;
      const float d = pred_line[col];
      if (!ValidDepth(d)) continue;
      ++sums.predicted;
      const double error = std::abs(focal_baseline / d - focal_baseline / g);
      sums.error_sum += error;
      if (error < 1.0) ++sums.within_1px;
      if (error < 2.0) ++sums.within_2px;
    }
  }
  return sums;
}

}  // namespace dispmvs::eval
