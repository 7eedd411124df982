#include "synth/photo_folder.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <set>
#include <stdexcept>
#include <vector>

#ifdef DISPMVS_HAVE_OPENCV
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#endif

namespace dispmvs::synth {
namespace {

namespace fs = std::filesystem;

bool HasPhotoExtension(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  static const std::set<std::string> kExtensions{".png", ".jpg", ".jpeg", ".bmp",
                                                 ".tif", ".tiff", ".webp"};
  return kExtensions.count(ext) > 0;
}

}  // namespace

bool PhotoFolderAvailable() {
#ifdef DISPMVS_HAVE_OPENCV
  return true;
#else
  return false;
#endif
}

PhotoSet LoadPhotoFolder(const std::string& folder, const PhotoFolderOptions& options,
                         std::ostream* warnings) {
  if (options.max_photos < 1 || options.min_side < 2 || options.max_side < options.min_side) {
    throw std::invalid_argument("photo folder: need max_photos >= 1 and 2 <= min_side <= max_side");
  }
  std::error_code error;
  if (!fs::is_directory(folder, error)) {
    throw std::invalid_argument("photo folder " + folder + ": not a directory");
  }
#ifndef DISPMVS_HAVE_OPENCV
  (void)warnings;
  throw std::runtime_error("photo folder " + folder +
                           ": this build has no image decoding (OpenCV was not found); "
                           "use procedural textures only");
#else
  std::vector<fs::path> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(folder)) {
    if (entry.is_regular_file() && HasPhotoExtension(entry.path())) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  PhotoSet photos;
  for (const fs::path& file : files) {
    if (static_cast<int>(photos.size()) >= options.max_photos) break;
    cv::Mat bgr = cv::imread(file.string(), cv::IMREAD_COLOR);
    if (bgr.empty()) {
      if (warnings) *warnings << "warning: cannot decode " << file.string() << ", skipped\n";
      continue;
    }
    if (std::min(bgr.rows, bgr.cols) < options.min_side) {
      if (warnings) {
        *warnings << "warning: " << file.string() << " is smaller than " << options.min_side
                  << " pixels, skipped\n";
      }
      continue;
    }
    const int longest = std::max(bgr.rows, bgr.cols);
    if (longest > options.max_side) {
      const double s = static_cast<double>(options.max_side) / longest;
      const cv::Size size(std::max(2, static_cast<int>(std::lround(bgr.cols * s))),
                          std::max(2, static_cast<int>(std::lround(bgr.rows * s))));
      cv::resize(bgr, bgr, size, 0, 0, cv::INTER_AREA);
    }
    cv::Mat rgb;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    rgb.convertTo(rgb, CV_32FC3, 1.0 / 255.0);
    // HWC (OpenCV) -> CHW, owning its memory.
    photos.push_back(torch::from_blob(rgb.data, {rgb.rows, rgb.cols, 3}, torch::kFloat)
                         .permute({2, 0, 1})
                         .contiguous());
  }
  if (photos.empty()) {
    throw std::invalid_argument("photo folder " + folder + ": no usable photo (" +
                                std::to_string(files.size()) + " image files)");
  }
  return photos;
#endif
}

}  // namespace dispmvs::synth
