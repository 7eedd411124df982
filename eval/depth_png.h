#pragma once
// Colourised depth and relative-error images for looking at an evaluation
// (dispmvs_eval --png_dir). Both use OpenCV's TURBO colour map (blue = low,
// red = high).

#include <filesystem>

#include <opencv2/core.hpp>

#include "colmap_io/dense_array.h"

namespace dispmvs::eval {

// Range [low, high] of the valid (finite, > 0) depths of `depth`, used as
// the colour scale of a view: the GT's, so that the GT and every prediction
// of the view share it. {0, 1} when nothing is valid; high > low always.
struct DepthRange {
  double low = 0;
  double high = 1;
};
DepthRange ValidDepthRange(const colmap_io::DenseArray& depth);

// CV_8UC3 (BGR): depth mapped linearly from range.low (blue) to range.high
// (red), values outside clamped; pixels without a valid depth black.
cv::Mat ColouriseDepth(const colmap_io::DenseArray& depth, const DepthRange& range);

// CV_8UC3 (BGR) from the relative-error image of SumDepthMetrics: 0 blue to
// max_rel_error (and above) red; GT surface without a prediction white; no
// GT black.
cv::Mat ColouriseRelError(const cv::Mat& rel_error, double max_rel_error);

// PNG-encodes `image` and writes it atomically (atomic_file.h), creating
// parent directories. Throws IoError naming `path`.
void WritePngAtomically(const cv::Mat& image, const std::filesystem::path& path);

}  // namespace dispmvs::eval
