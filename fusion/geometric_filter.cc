#include "fusion/geometric_filter.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "fusion/input_checks.h"

namespace dispmvs::fusion {
namespace {

void CheckNonNegativeFinite(double value, const char* field) {
  if (!std::isfinite(value) || value < 0.0) {
    throw std::invalid_argument(std::string("GeometricFilterOptions.") + field +
                                " must be finite and >= 0, got " + std::to_string(value));
  }
}

// The map from reference camera coordinates to target camera coordinates:
// X_target = rotation * X_reference + offset.
void RelativePose(const DepthView& from, const DepthView& to, Eigen::Matrix3d* rotation,
                  Eigen::Vector3d* offset) {
  *rotation = to.R * from.R.transpose();
  *offset = to.t - *rotation * from.t;
}

// Per pixel, whether at least `min_support` of the pixels of the
// (2 radius + 1)^2 window around it that lie inside the image pass: window
// sums of `pass` from its summed-area table.
std::vector<uint8_t> SupportedPixels(const std::vector<uint8_t>& pass, int width, int height,
                                     int radius, double min_support) {
  const std::size_t stride = static_cast<std::size_t>(width) + 1;
  // table[(r + 1) * stride + (c + 1)]: passing pixels in rows <= r, cols <= c.
  std::vector<uint32_t> table(stride * (static_cast<std::size_t>(height) + 1), 0u);
  for (int row = 0; row < height; ++row) {
    uint32_t row_sum = 0;
    for (int col = 0; col < width; ++col) {
      row_sum += pass[static_cast<std::size_t>(row) * width + col];
      table[(row + 1) * stride + col + 1] = table[row * stride + col + 1] + row_sum;
    }
  }
  std::vector<uint8_t> supported(pass.size(), 0u);
  for (int row = 0; row < height; ++row) {
    const int top = std::max(row - radius, 0), bottom = std::min(row + radius, height - 1);
    for (int col = 0; col < width; ++col) {
      const std::size_t index = static_cast<std::size_t>(row) * width + col;
      if (!pass[index]) continue;
      const int left = std::max(col - radius, 0), right = std::min(col + radius, width - 1);
      const uint32_t passing = table[(bottom + 1) * stride + right + 1] -
                               table[top * stride + right + 1] -
                               table[(bottom + 1) * stride + left] + table[top * stride + left];
      const double inside = static_cast<double>(bottom - top + 1) * (right - left + 1);
      supported[index] = passing >= min_support * inside;
    }
  }
  return supported;
}

}  // namespace

void GeometricFilterOptions::Check() const {
  CheckNonNegativeFinite(max_reprojection_error, "max_reprojection_error");
  CheckNonNegativeFinite(max_relative_depth_error, "max_relative_depth_error");
  if (min_consistent_views < 0 || min_consistent_views > kMaxSourceViews) {
    throw std::invalid_argument("GeometricFilterOptions.min_consistent_views must be in [0, " +
                                std::to_string(kMaxSourceViews) + "], got " +
                                std::to_string(min_consistent_views));
  }
  if (!std::isfinite(min_confidence)) {
    throw std::invalid_argument("GeometricFilterOptions.min_confidence must be finite");
  }
  if (!(min_support >= 0.0 && min_support <= 1.0)) {
    throw std::invalid_argument("GeometricFilterOptions.min_support must be in [0, 1], got " +
                                std::to_string(min_support));
  }
  if (support_radius < 1 || support_radius > kMaxSupportRadius) {
    throw std::invalid_argument("GeometricFilterOptions.support_radius must be in [1, " +
                                std::to_string(kMaxSupportRadius) + "], got " +
                                std::to_string(support_radius));
  }
}

GeometricFilterOptions SupportFilterDefaults() {
  GeometricFilterOptions options;
  options.max_reprojection_error = 2.0;
  options.max_relative_depth_error = 0.02;
  options.min_support = 0.6;
  options.support_radius = 2;
  return options;
}

void ValidateDepthView(const DepthView& view, const std::string& what) {
  internal::CheckMap(view.depth, 1, what + " depth");
  if (!view.confidence.empty()) {
    internal::CheckMap(view.confidence, 1, what + " confidence");
    internal::CheckSameSize(view.confidence, view.depth, what + " confidence");
  }
  internal::CheckIntrinsics(view.K, what);
  internal::CheckRotation(view.R, what);
  internal::CheckFinite(view.t, what + " translation t");
}

bool HasUsableDepth(const DepthView& view, int row, int col, double min_confidence) {
  const std::size_t index = static_cast<std::size_t>(row) * view.depth.width() + col;
  if (!internal::IsValidDepth(view.depth.data()[index])) return false;
  // NaN confidence fails the comparison, as it should.
  return view.confidence.empty() ||
         static_cast<double>(view.confidence.data()[index]) >= min_confidence;
}

PairConsistency::PairConsistency(const DepthView& reference, const DepthView& source,
                                 const GeometricFilterOptions& options)
    : source_(source),
      max_reprojection_error_squared_(options.max_reprojection_error *
                                      options.max_reprojection_error),
      max_relative_depth_error_(options.max_relative_depth_error),
      min_confidence_(options.min_confidence) {
  Eigen::Matrix3d rotation;
  Eigen::Vector3d offset;
  RelativePose(reference, source, &rotation, &offset);
  forward_ = source.K * rotation * reference.K.inverse();
  forward_offset_ = source.K * offset;
  RelativePose(source, reference, &rotation, &offset);
  backward_ = reference.K * rotation * source.K.inverse();
  backward_offset_ = reference.K * offset;
}

bool PairConsistency::Check(int row, int col, double reference_depth, Match* match) const {
  // Into the source. K's last row is (0, 0, 1), so the third coordinate is
  // the source-camera depth; points behind the source never match.
  const Eigen::Vector3d pixel(col, row, 1.0);
  const Eigen::Vector3d projected = reference_depth * (forward_ * pixel) + forward_offset_;
  if (!(projected.z() > 0.0)) return false;
  const double source_col = projected.x() / projected.z();
  const double source_row = projected.y() / projected.z();
  const int width = source_.depth.width();
  const int height = source_.depth.height();
  // Inside the map once rounded to the nearest pixel (NaN fails too).
  if (!(source_col > -0.5 && source_col < width - 0.5 && source_row > -0.5 &&
        source_row < height - 0.5)) {
    return false;
  }
  const int nearest_col = static_cast<int>(std::floor(source_col + 0.5));
  const int nearest_row = static_cast<int>(std::floor(source_row + 0.5));
  if (!HasUsableDepth(source_, nearest_row, nearest_col, min_confidence_)) return false;
  const float source_depth =
      source_.depth.data()[static_cast<std::size_t>(nearest_row) * width + nearest_col];

  // That source pixel back into the reference.
  const Eigen::Vector3d source_pixel(nearest_col, nearest_row, 1.0);
  const Eigen::Vector3d reprojected =
      static_cast<double>(source_depth) * (backward_ * source_pixel) + backward_offset_;
  const double reprojected_depth = reprojected.z();
  if (!(reprojected_depth > 0.0)) return false;
  const double d_col = reprojected.x() / reprojected_depth - col;
  const double d_row = reprojected.y() / reprojected_depth - row;
  if (!(d_col * d_col + d_row * d_row <= max_reprojection_error_squared_)) return false;
  if (!(std::abs(reprojected_depth - reference_depth) <=
        max_relative_depth_error_ * reference_depth)) {
    return false;
  }
  match->row = nearest_row;
  match->col = nearest_col;
  match->depth = source_depth;
  return true;
}

GeometricFilterResult FilterDepthMap(const DepthView& reference,
                                     const std::vector<const DepthView*>& sources,
                                     const GeometricFilterOptions& options) {
  options.Check();
  ValidateDepthView(reference, "FilterDepthMap: reference");
  if (sources.size() > static_cast<std::size_t>(kMaxSourceViews)) {
    throw std::invalid_argument("FilterDepthMap: " + std::to_string(sources.size()) +
                                " source views, at most " + std::to_string(kMaxSourceViews) +
                                " are supported");
  }
  std::vector<PairConsistency> pairs;
  pairs.reserve(sources.size());
  for (std::size_t i = 0; i < sources.size(); ++i) {
    const std::string what = "FilterDepthMap: source view " + std::to_string(i);
    if (sources[i] == nullptr) throw std::invalid_argument(what + " is null");
    ValidateDepthView(*sources[i], what);
    pairs.emplace_back(reference, *sources[i], options);
  }

  const int width = reference.depth.width();
  const int height = reference.depth.height();
  const std::size_t num_pixels = static_cast<std::size_t>(width) * height;
  GeometricFilterResult result;
  result.depth = colmap_io::DenseArray(width, height, 1, 0.0f);
  result.consistent_mask.assign(num_pixels, 0u);
  result.num_consistent.assign(num_pixels, 0u);
  const float* reference_depth = reference.depth.data();
  float* kept_depth = result.depth.data();
  PairConsistency::Match match;
  std::vector<uint8_t> pass(num_pixels, 0u);
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      if (!HasUsableDepth(reference, row, col, options.min_confidence)) continue;
      const std::size_t index = static_cast<std::size_t>(row) * width + col;
      const float depth = reference_depth[index];
      uint32_t mask = 0;
      int count = 0;
      for (std::size_t s = 0; s < pairs.size(); ++s) {
        if (pairs[s].Check(row, col, depth, &match)) {
          mask |= uint32_t{1} << s;
          ++count;
        }
      }
      result.consistent_mask[index] = mask;
      result.num_consistent[index] = static_cast<uint8_t>(count);
      pass[index] = count >= options.min_consistent_views;
    }
  }
  if (options.min_support > 0) {
    pass = SupportedPixels(pass, width, height, options.support_radius, options.min_support);
  }
  for (std::size_t index = 0; index < num_pixels; ++index) {
    if (!pass[index]) continue;
    kept_depth[index] = reference_depth[index];
    ++result.num_kept;
  }
  return result;
}

}  // namespace dispmvs::fusion
