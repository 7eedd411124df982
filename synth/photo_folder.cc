#include "synth/photo_folder.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <set>
#include <utility>
#include <stdexcept>
#include <vector>

#ifdef DISPMVS_HAVE_OPENCV
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#endif

#include "synth/netpbm.h"

namespace dispmvs::synth {
namespace {

namespace fs = std::filesystem;

std::string LowerExtension(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

bool IsNetpbm(const fs::path& path) {
  const std::string ext = LowerExtension(path);
  return ext == ".ppm" || ext == ".pgm";
}

bool HasPhotoExtension(const fs::path& path) {
  static const std::set<std::string> kExtensions{".png", ".jpg", ".jpeg", ".bmp", ".tif",
                                                 ".tiff", ".webp", ".ppm", ".pgm"};
  return kExtensions.count(LowerExtension(path)) > 0;
}

// Output size of a shrink of the longest side to max_side (aspect kept).
std::pair<int64_t, int64_t> ShrunkSize(int64_t rows, int64_t cols, int max_side) {
  const double s = static_cast<double>(max_side) / static_cast<double>(std::max(rows, cols));
  return {std::max<int64_t>(2, std::lround(static_cast<double>(rows) * s)),
          std::max<int64_t>(2, std::lround(static_cast<double>(cols) * s))};
}

void Warn(std::ostream* warnings, const std::string& line) {
  if (warnings) *warnings << "warning: " << line << "\n";
}

// Decodes one file as a [3, H, W] RGB tensor in [0, 1], shrunk to max_side;
// an undefined tensor (after a warning) when it cannot be used.
torch::Tensor DecodePhoto(const fs::path& file, const PhotoFolderOptions& options, std::ostream* warnings) {
  if (IsNetpbm(file)) {
    torch::Tensor rgb;
    try {
      rgb = ReadNetpbm(file.string());
    } catch (const std::runtime_error& e) {
      Warn(warnings, std::string("cannot decode ") + e.what() + ", skipped");
      return {};
    }
    const int64_t rows = rgb.size(1), cols = rgb.size(2);
    if (std::min(rows, cols) < options.min_side) {
      Warn(warnings, file.string() + " is smaller than " + std::to_string(options.min_side) + " pixels, skipped");
      return {};
    }
    if (std::max(rows, cols) <= options.max_side) return rgb;
    // Area averaging, like OpenCV's INTER_AREA for the other formats.
    const auto [new_rows, new_cols] = ShrunkSize(rows, cols, options.max_side);
    return torch::adaptive_avg_pool2d(rgb.unsqueeze(0), {new_rows, new_cols}).squeeze(0).contiguous();
  }
#ifndef DISPMVS_HAVE_OPENCV
  Warn(warnings, "cannot decode " + file.string() +
                     ": this build reads only PPM/PGM photos (OpenCV was not found), skipped");
  return {};
#else
  cv::Mat bgr = cv::imread(file.string(), cv::IMREAD_COLOR);
  if (bgr.empty()) {
    Warn(warnings, "cannot decode " + file.string() + ", skipped");
    return {};
  }
  if (std::min(bgr.rows, bgr.cols) < options.min_side) {
    Warn(warnings, file.string() + " is smaller than " + std::to_string(options.min_side) + " pixels, skipped");
    return {};
  }
  if (std::max(bgr.rows, bgr.cols) > options.max_side) {
    const auto [new_rows, new_cols] = ShrunkSize(bgr.rows, bgr.cols, options.max_side);
    cv::resize(bgr, bgr, cv::Size(static_cast<int>(new_cols), static_cast<int>(new_rows)), 0, 0, cv::INTER_AREA);
  }
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  rgb.convertTo(rgb, CV_32FC3, 1.0 / 255.0);
  // HWC (OpenCV) -> CHW, owning its memory.
  return torch::from_blob(rgb.data, {rgb.rows, rgb.cols, 3}, torch::kFloat).permute({2, 0, 1}).contiguous();
#endif
}

}  // namespace

bool PhotoFolderDecodesAllFormats() {
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
  std::vector<fs::path> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(folder)) {
    if (entry.is_regular_file() && HasPhotoExtension(entry.path())) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  PhotoSet photos;
  for (const fs::path& file : files) {
    if (static_cast<int>(photos.size()) >= options.max_photos) break;
    torch::Tensor photo = DecodePhoto(file, options, warnings);
    if (photo.defined()) photos.push_back(std::move(photo));
  }
  if (photos.empty()) {
    throw std::invalid_argument("photo folder " + folder + ": no usable photo (" + std::to_string(files.size()) +
                                " image files" +
                                (PhotoFolderDecodesAllFormats() ? "" : "; this build reads only PPM/PGM") + ")");
  }
  return photos;
}

}  // namespace dispmvs::synth
