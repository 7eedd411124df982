#include "eval/confidence_ranking.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>


namespace dispmvs::eval {

int64_t ConfidenceRankingSums::total() const {
  int64_t sum = 0;
  for (const int64_t n : pixels) sum += n;
  return sum;
}

ConfidenceRankingSums& ConfidenceRankingSums::operator+=(const ConfidenceRankingSums& other) {
  if (other.pixels.empty()) return *this;
  if (pixels.empty()) {
    pixels.assign(kBins, 0);
    within_2.assign(kBins, 0);
  }
  for (int b = 0; b < kBins; ++b) {
    pixels[b] += other.pixels[b];
    within_2[b] += other.within_2[b];
  }
  return *this;
}

double ConfidenceRankingSums::ShareWithin2AtCoverage(double coverage) const {
  if (!(coverage > 0 && coverage <= 1)) {
    throw std::invalid_argument("ShareWithin2AtCoverage: coverage must be in (0, 1]");
  }
  const int64_t count = total();
  if (count == 0) return std::numeric_limits<double>::quiet_NaN();
  const double wanted = coverage * static_cast<double>(count);
  double kept = 0, right = 0;
  for (int b = kBins - 1; b >= 0 && kept < wanted; --b) {
    if (pixels[b] == 0) continue;
    const double take = std::min(static_cast<double>(pixels[b]), wanted - kept);
    right += take / static_cast<double>(pixels[b]) * static_cast<double>(within_2[b]);
    kept += take;
  }
  return right / kept;
}

ConfidenceRankingSums SumConfidenceRanking(const cv::Mat& rel_error, const colmap_io::DenseArray& confidence) {
  if (rel_error.type() != CV_32FC1 || confidence.width() != rel_error.cols ||
      confidence.height() != rel_error.rows || confidence.channels() != 1) {
    throw std::invalid_argument("the confidence map is not a one-channel map of the depth map's size");
  }
  ConfidenceRankingSums sums;
  sums.pixels.assign(ConfidenceRankingSums::kBins, 0);
  sums.within_2.assign(ConfidenceRankingSums::kBins, 0);
  const float* c = confidence.data();
  for (int row = 0; row < rel_error.rows; ++row) {
    const float* error = rel_error.ptr<float>(row);
    for (int col = 0; col < rel_error.cols; ++col) {
      if (error[col] < 0) continue;  // no prediction or no ground truth
      const float value = c[static_cast<std::size_t>(row) * rel_error.cols + col];
      const double clamped = std::isfinite(value) ? std::clamp(static_cast<double>(value), 0.0, 1.0) : 0.0;
      const int bin = std::min(ConfidenceRankingSums::kBins - 1,
                               static_cast<int>(clamped * ConfidenceRankingSums::kBins));
      ++sums.pixels[bin];
      if (error[col] < 0.02f) ++sums.within_2[bin];
    }
  }
  return sums;
}

}  // namespace dispmvs::eval
