#pragma once
// Accuracy of one depth map against a ground-truth depth map.
//
// Pixels. A ground-truth (GT) pixel is valid when its depth is finite and
// > 0 (0 = no surface). A prediction is valid when it is finite and > 0;
// anything else (0, negative, NaN, inf) counts as missing. Over the valid GT
// pixels:
//   coverage            = predicted / gt_pixels
//   abs_rel             = mean of |d - gt| / gt over the predicted pixels
//   median_rel          = median of |d - gt| / gt over the predicted pixels
//   within_X_of_predicted = fraction of the predicted pixels with
//                         |d - gt| / gt < X % (X = 1, 2, 5)
//   within_X_of_gt      = the same count divided by gt_pixels instead, i.e.
//                         a missing prediction counts as a miss
// (so within_X_of_gt = within_X_of_predicted * coverage). Predictions where
// the GT has no surface are not scored; they are counted in
// predicted_without_gt.
//
// NOTE: unlike train/depth_metrics.h (which adds relative error 1 for every
// missing pixel), abs_rel here is over predicted pixels only; read it together
// with coverage.
//
// Sizes. A map may be smaller than its GT (COLMAP's max_image_size). It is
// then compared at the map's size, sampling the GT at the nearest pixel of
// the same continuous position, in COLMAP's dense convention (the one
// stereo_fusion uses): pixel (col, row) of a map scaled by s_x = map_width /
// image_width, s_y = map_height / image_height corresponds to image position
// (col / s_x, row / s_y), raw pixel indices with no half-pixel shift. With the
// GT at image size (W, H) that is GT pixel (round(col * W / map_width),
// round(row * H / map_height)), halves rounded up. The map must be a clean
// down-scale of the GT: see IsCleanScale().
//
// Sums accumulate: add the sums of several views, then Finalize(), to get
// pixel-weighted overall numbers. The median comes from a histogram of the
// relative errors (RelErrorHistogram), so it accumulates too.

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "colmap_io/dense_array.h"

namespace dispmvs::eval {

// Counts of relative errors in logarithmic bins: kBinsPerDecade bins per
// decade from kMinError to kMaxError (bin width 0.115 %), plus one bin for
// [0, kMinError) and one for [kMaxError, inf). Each bin also sums its values.
// Median() takes, for the median rank, the mean of the values in the bin
// holding it: always within that bin, so within 0.115 % (relative) of the
// exact median for values in [kMinError, kMaxError), and exact when that
// bin's values are all equal (e.g. a constant relative error).
class RelErrorHistogram {
 public:
  static constexpr double kMinError = 1e-7;
  static constexpr double kMaxError = 1e3;
  static constexpr int kBinsPerDecade = 2000;
  static constexpr int kNumDecades = 10;  // log10(kMaxError / kMinError)

  void Add(double rel_error);
  RelErrorHistogram& operator+=(const RelErrorHistogram& other);
  int64_t count() const { return count_; }
  // NaN when empty. For an even count, the mean of the two middle ranks'
  // values.
  double Median() const;

 private:
  double ValueAtRank(int64_t rank) const;
  // Allocated on first use (most maps have pixels, but empty sums stay small).
  std::vector<int64_t> bins_;
  std::vector<double> sums_;  // sum of the values in each bin
  int64_t count_ = 0;
};

struct DepthMetricSums {
  int64_t gt_pixels = 0;             // valid GT pixels (at the map's size)
  int64_t predicted = 0;             // ... with a valid prediction
  int64_t predicted_without_gt = 0;  // valid predictions where GT has no surface
  int64_t within_1 = 0;              // predicted with rel. error < 1 %
  int64_t within_2 = 0;              // ... < 2 %
  int64_t within_5 = 0;              // ... < 5 %
  double abs_rel_sum = 0;            // sum of |d - gt| / gt over predicted
  RelErrorHistogram rel_errors;

  DepthMetricSums& operator+=(const DepthMetricSums& other);
};

// Fractions (not percent). NaN where the denominator is 0: coverage and the
// *_of_gt fractions without GT pixels, the others without predictions.
struct DepthMetrics {
  int64_t gt_pixels = 0;
  int64_t predicted = 0;
  int64_t predicted_without_gt = 0;
  double coverage = 0;
  double abs_rel = 0;
  double median_rel = 0;
  double within_1_of_predicted = 0, within_2_of_predicted = 0, within_5_of_predicted = 0;
  double within_1_of_gt = 0, within_2_of_gt = 0, within_5_of_gt = 0;
};

DepthMetrics Finalize(const DepthMetricSums& sums);

// True when a map of map_width x map_height can come from an image of
// gt_width x gt_height by one scale factor s <= 1 with each side rounded to
// the nearest integer (COLMAP's max_image_size rule): some s satisfies
// |map_width - s * gt_width| <= 0.5 and |map_height - s * gt_height| <= 0.5
// (0.01 pixel of tolerance absorbs COLMAP's single-precision arithmetic).
// Equal sizes are clean; sizes < 1 are not.
bool IsCleanScale(int map_width, int map_height, int gt_width, int gt_height);

// The GT pixel index compared with map index `index` along an axis of map
// size `map_size` and GT size `gt_size`: round(index * gt_size / map_size)
// (halves up), clamped to [0, gt_size - 1].
int NearestGtIndex(int index, int map_size, int gt_size);

// Relative-error image codes written by SumDepthMetrics (besides values >= 0).
constexpr float kRelErrorMissing = -1.0f;  // GT surface, no prediction
constexpr float kRelErrorNoGt = -2.0f;     // no GT surface

// Scores `prediction` against `gt` (both 1-channel). Throws
// std::invalid_argument when a map is empty or has more than one channel, or
// when the prediction's size is not a clean down-scale of the GT's
// (IsCleanScale). When `rel_error` is not null it receives a CV_32FC1 image of
// the prediction's size: the relative error where both exist, else
// kRelErrorMissing or kRelErrorNoGt.
DepthMetricSums SumDepthMetrics(const colmap_io::DenseArray& prediction,
                                const colmap_io::DenseArray& gt, cv::Mat* rel_error = nullptr);

// ---- Disparity error of a view in a rectified stereo pair (rectified_pair.h)
//
// For an image with a rectified partner at baseline B, depth z and disparity
// are tied by disparity = f_x B / z + doffs, doffs being the principal-point
// offset of the pair; doffs cancels in the difference, so the error of a
// predicted pixel is |f_x B / d - f_x B / gt| in pixels. f_x is the camera's
// focal length scaled to the GT map's width, so the error stays in pixels of
// the GT's resolution when the map itself is smaller (pixels are matched as
// in SumDepthMetrics). Over the same pixels as DepthMetricSums:
//   mean_error              mean disparity error over the predicted pixels
//   within_Npx_of_predicted predicted pixels with error < N px (N = 1, 2),
//                           of the predicted pixels
//   within_Npx_of_gt        the same count, of all GT pixels
// The sums accumulate over views like DepthMetricSums; `views` counts the
// views that had a partner, so a type whose views have none reports
// "not applicable" (DisparityMetrics::applicable false).

struct DisparityMetricSums {
  int64_t views = 0;       // views with a rectified partner summed in here
  int64_t gt_pixels = 0;   // valid GT pixels (at the map's size)
  int64_t predicted = 0;   // ... with a valid prediction
  int64_t within_1px = 0;  // predicted with disparity error < 1 px
  int64_t within_2px = 0;  // ... < 2 px
  double error_sum = 0;    // sum of the disparity errors (px) over predicted

  DisparityMetricSums& operator+=(const DisparityMetricSums& other);
};

// Fractions (not percent). Where not applicable every value is NaN and the
// counts 0; where applicable, NaN as in DepthMetrics (no GT pixel / no
// prediction).
struct DisparityMetrics {
  bool applicable = false;
  int64_t gt_pixels = 0;
  int64_t predicted = 0;
  double mean_error = 0;
  double within_1px_of_predicted = 0, within_2px_of_predicted = 0;
  double within_1px_of_gt = 0, within_2px_of_gt = 0;
};

DisparityMetrics Finalize(const DisparityMetricSums& sums);

// Scores `prediction` against `gt` in disparity for a view whose
// focal_baseline = f_x B (f_x at the GT's resolution, B in the depth maps'
// units; so the disparity of depth z is focal_baseline / z pixels). The
// result has views = 1. Throws std::invalid_argument as SumDepthMetrics, and
// when focal_baseline is not finite and > 0.
DisparityMetricSums SumDisparityMetrics(const colmap_io::DenseArray& prediction,
                                        const colmap_io::DenseArray& gt, double focal_baseline);

}  // namespace dispmvs::eval
