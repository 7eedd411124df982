#pragma once
// How well a confidence map ranks its depth map's pixels: among the most
// confident 50 / 75 / 90 / 100 % of the predicted pixels with ground truth,
// the share within 2 % depth error (a precision/coverage curve). A
// confidence that means something keeps the right pixels first, so the
// share falls as the coverage grows; one that says nothing gives the same
// share at every coverage.
//
// The pixels are counted in kBins equal bins of confidence in [0, 1], so
// sums of many views and workspaces add up exactly; the share at a coverage
// that ends inside a bin counts that bin's pixels pro rata (a bin 0.1 % of
// confidence wide).

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "colmap_io/dense_array.h"

namespace dispmvs::eval {

struct ConfidenceRankingSums {
  static constexpr int kBins = 1000;
  // Per bin: predicted pixels with ground truth, and those within 2 %.
  // Empty for sums of no map.
  std::vector<int64_t> pixels, within_2;

  int64_t total() const;
  ConfidenceRankingSums& operator+=(const ConfidenceRankingSums& other);
  // The share within 2 % among the `coverage` (in (0, 1]) most confident
  // pixels; NaN without pixels. Throws std::invalid_argument for a coverage
  // outside (0, 1].
  double ShareWithin2AtCoverage(double coverage) const;
};

// The coverages the reports show.
inline const std::vector<double> kRankingCoverages{0.5, 0.75, 0.9, 1.0};

// The ranking of one map: every pixel with a relative error (`rel_error`,
// the CV_32FC1 image SumDepthMetrics writes: >= 0 where both the prediction
// and the ground truth exist) under its confidence, clamped to [0, 1] (a
// non-finite confidence counts as 0). The confidence map must be one channel
// of rel_error's size; throws std::invalid_argument otherwise.
ConfidenceRankingSums SumConfidenceRanking(const cv::Mat& rel_error, const colmap_io::DenseArray& confidence);

}  // namespace dispmvs::eval
