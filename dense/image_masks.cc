#include "dense/image_masks.h"

#include <opencv2/imgproc.hpp>

#include "colmap_io/error.h"
#include "colmap_io/image_io.h"

namespace dispmvs::dense {

namespace fs = std::filesystem;

ImageMasks::ImageMasks(const fs::path& mask_dir) : dir_(mask_dir) {
  if (dir_.empty() || !fs::is_directory(dir_)) {
    throw colmap_io::IoError(mask_dir.string(), "the mask path is not a folder");
  }
}

std::optional<fs::path> ImageMasks::PathOf(const std::string& image_name) const {
  if (!enabled()) return std::nullopt;
  const fs::path with_suffix = dir_ / (image_name + ".png");
  if (fs::is_regular_file(with_suffix)) return with_suffix;
  const std::string suffix = ".png";
  if (image_name.size() > suffix.size() &&
      image_name.compare(image_name.size() - suffix.size(), suffix.size(), suffix) == 0) {
    const fs::path as_named = dir_ / image_name;
    if (fs::is_regular_file(as_named)) return as_named;
  }
  return std::nullopt;
}

cv::Mat ImageMasks::Read(const std::string& image_name, int width, int height) const {
  const std::optional<fs::path> path = PathOf(image_name);
  if (!path) return {};
  const cv::Mat rgb = colmap_io::ReadImageRgb(*path);  // checked header, bounded memory
  cv::Mat red;
  cv::extractChannel(rgb, red, 0);
  if (red.cols != width || red.rows != height) {
    // A box filter, as COLMAP rescales masks: a pixel stays ignored only
    // where everything it covers is 0.
    cv::Mat resized;
    cv::resize(red, resized, cv::Size(width, height), 0, 0, cv::INTER_AREA);
    red = resized;
  }
  cv::Mat used;
  cv::compare(red, 0, used, cv::CMP_NE);  // 255 where used
  return used / 255;
}

std::size_t ImageMasks::Apply(const std::string& image_name, fusion::DepthView* view) const {
  const int width = view->depth.width();
  const int height = view->depth.height();
  const cv::Mat used = Read(image_name, width, height);
  if (used.empty()) return 0;
  std::size_t ignored = 0;
  float* depth = view->depth.data();
  for (int row = 0; row < height; ++row) {
    const uint8_t* mask_row = used.ptr<uint8_t>(row);
    for (int col = 0; col < width; ++col) {
      if (mask_row[col] != 0) continue;
      depth[static_cast<std::size_t>(row) * width + col] = 0;
      ++ignored;
    }
  }
  return ignored;
}

std::size_t ImageMasks::CountWithMask(const std::vector<std::string>& image_names) const {
  std::size_t count = 0;
  for (const std::string& name : image_names) count += PathOf(name) ? 1 : 0;
  return count;
}

}  // namespace dispmvs::dense
