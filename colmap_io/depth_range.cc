#include "colmap_io/depth_range.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace dispmvs::colmap_io {
namespace {

void CheckFraction(double value, const char* name) {
  if (!(value >= 0.0 && value <= 1.0)) {
    throw std::invalid_argument(std::string("DepthRangeOptions.") + name +
                                " must be in [0, 1], got " + std::to_string(value));
  }
}

// COLMAP's indexing: sorted[floor(n * p)], clamped for p == 1.
double PickPercentile(const std::vector<double>& sorted, double fraction) {
  const auto index = static_cast<std::size_t>(
      std::floor(static_cast<double>(sorted.size()) * fraction));
  return sorted[std::min(index, sorted.size() - 1)];
}

}  // namespace

void DepthRangeOptions::Check() const {
  CheckFraction(min_percentile, "min_percentile");
  CheckFraction(max_percentile, "max_percentile");
  if (min_percentile > max_percentile) {
    throw std::invalid_argument("DepthRangeOptions.min_percentile must not exceed max_percentile");
  }
  // s >= 1 would make the lower bound zero or negative, which is no depth.
  if (!(stretch_ratio >= 0.0 && stretch_ratio < 1.0)) {
    throw std::invalid_argument("DepthRangeOptions.stretch_ratio must be in [0, 1), got " +
                                std::to_string(stretch_ratio));
  }
  if (min_num_points < 1) {
    throw std::invalid_argument("DepthRangeOptions.min_num_points must be at least 1");
  }
}

DepthRange ComputeDepthRange(const SparseModel& model, image_t image_id,
                             const DepthRangeOptions& options) {
  options.Check();
  const auto image_it = model.images.find(image_id);
  if (image_it == model.images.end()) {
    throw std::invalid_argument("ComputeDepthRange: no image with id " +
                                std::to_string(image_id) + " in the model");
  }
  const Image& image = image_it->second;
  // Only the third row of [R | t] matters for the depth.
  const Eigen::Vector3d z_row = image.RotationMatrix().row(2).transpose();
  const double z_offset = image.tvec.z();

  std::vector<double> depths;
  depths.reserve(image.points2D.size());
  for (const Point2D& point2D : image.points2D) {
    if (!point2D.HasPoint3D()) continue;
    const auto point_it = model.points3D.find(point2D.point3D_id);
    if (point_it == model.points3D.end()) continue;
    const double depth = z_row.dot(point_it->second.xyz) + z_offset;
    if (std::isfinite(depth) && depth > 0.0) depths.push_back(depth);
  }

  DepthRange range;
  range.num_points = depths.size();
  if (depths.size() < options.min_num_points) return range;

  std::sort(depths.begin(), depths.end());
  range.d_min = (1.0 - options.stretch_ratio) * PickPercentile(depths, options.min_percentile);
  range.d_max = (1.0 + options.stretch_ratio) * PickPercentile(depths, options.max_percentile);
  range.valid = true;
  return range;
}

std::map<image_t, DepthRange> ComputeDepthRanges(const SparseModel& model,
                                                 const DepthRangeOptions& options) {
  std::map<image_t, DepthRange> ranges;
  for (const auto& [image_id, image] : model.images) {
    ranges.emplace(image_id, ComputeDepthRange(model, image_id, options));
  }
  return ranges;
}

DepthRange FallbackDepthRange(const std::map<image_t, DepthRange>& ranges) {
  DepthRange fallback;
  for (const auto& [image_id, range] : ranges) {
    if (!range.valid) continue;
    if (!fallback.valid) {
      fallback.d_min = range.d_min;
      fallback.d_max = range.d_max;
      fallback.valid = true;
    } else {
      fallback.d_min = std::min(fallback.d_min, range.d_min);
      fallback.d_max = std::max(fallback.d_max, range.d_max);
    }
    fallback.num_points += range.num_points;
  }
  return fallback;
}

}  // namespace dispmvs::colmap_io
