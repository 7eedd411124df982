#include "eval/depth_png.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"
#include "eval/depth_metrics.h"

namespace dispmvs::eval {
namespace {

bool ValidDepth(float depth) { return std::isfinite(depth) && depth > 0.0f; }

uchar ToByte(double t) {
  return static_cast<uchar>(std::lround(255.0 * std::clamp(t, 0.0, 1.0)));
}

}  // namespace

DepthRange ValidDepthRange(const colmap_io::DenseArray& depth) {
  double low = std::numeric_limits<double>::infinity();
  double high = -std::numeric_limits<double>::infinity();
  const std::size_t n = static_cast<std::size_t>(depth.width()) * depth.height();
  for (std::size_t i = 0; i < n && i < depth.size(); ++i) {
    const float d = depth.data()[i];
    if (!ValidDepth(d)) continue;
    low = std::min(low, static_cast<double>(d));
    high = std::max(high, static_cast<double>(d));
  }
  if (!(low <= high)) return DepthRange{};
  if (!(high > low)) high = low + std::max(1e-6, 1e-6 * low);
  return DepthRange{low, high};
}

cv::Mat ColouriseDepth(const colmap_io::DenseArray& depth, const DepthRange& range) {
  const int width = depth.width();
  const int height = depth.height();
  cv::Mat grey(height, width, CV_8UC1);
  cv::Mat valid(height, width, CV_8UC1);
  for (int row = 0; row < height; ++row) {
    const float* line = depth.data() + static_cast<std::size_t>(row) * width;
    for (int col = 0; col < width; ++col) {
      const float d = line[col];
      const bool ok = ValidDepth(d);
      valid.at<uchar>(row, col) = ok ? 1 : 0;
      grey.at<uchar>(row, col) = ok ? ToByte((d - range.low) / (range.high - range.low)) : 0;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  colour.setTo(cv::Scalar(0, 0, 0), valid == 0);
  return colour;
}

cv::Mat ColouriseRelError(const cv::Mat& rel_error, double max_rel_error) {
  CV_Assert(rel_error.type() == CV_32FC1);
  cv::Mat grey(rel_error.size(), CV_8UC1);
  cv::Mat missing(rel_error.size(), CV_8UC1);
  cv::Mat no_gt(rel_error.size(), CV_8UC1);
  for (int row = 0; row < rel_error.rows; ++row) {
    for (int col = 0; col < rel_error.cols; ++col) {
      const float e = rel_error.at<float>(row, col);
      missing.at<uchar>(row, col) = e == kRelErrorMissing ? 1 : 0;
      no_gt.at<uchar>(row, col) = e == kRelErrorNoGt ? 1 : 0;
      grey.at<uchar>(row, col) = e >= 0 ? ToByte(e / max_rel_error) : 0;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  colour.setTo(cv::Scalar(255, 255, 255), missing != 0);
  colour.setTo(cv::Scalar(0, 0, 0), no_gt != 0);
  return colour;
}

void WritePngAtomically(const cv::Mat& image, const std::filesystem::path& path) {
  std::vector<uchar> bytes;
  bool encoded = false;
  try {
    encoded = cv::imencode(".png", image, bytes);
  } catch (const cv::Exception& error) {
    throw colmap_io::IoError(path.string(), std::string("cannot encode PNG: ") + error.what());
  }
  if (!encoded) throw colmap_io::IoError(path.string(), "cannot encode PNG");
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  });
}

}  // namespace dispmvs::eval
