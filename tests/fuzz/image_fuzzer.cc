// libFuzzer target for reading a workspace image for its camera
// (ReadImageHeader, ReadImageRgb, ReadImageForCamera): the input is the whole
// image file, in any format.
//
// OpenCV, libtiff and libwebp are linked as Debian ships them,
// uninstrumented: the target tests what the project does before and around
// the decoders (the format and header checks that decide what reaches a
// decoder at all, the memory bounds, type and channel handling, the size
// check against the camera, the resize and the intrinsics). Only what
// colmap_io/image_header.cc accepts reaches OpenCV, and that is the code
// whose branches the fuzzer sees.
//
// Properties checked, besides "no crash, no abort inside a decoder, no
// sanitizer report, no huge allocation" (run with -rss_limit_mb and
// -malloc_limit_mb):
//  * the functions throw nothing but IoError;
//  * an accepted image has the header's size, is CV_32FC3, non-empty, with
//    every value in [0, 1];
//  * for a PINHOLE camera of the decoded size, ReadImageForCamera returns the
//    same pixels and K when nothing is resized, and the size of
//    ComputeResizedSize and K of ScaleIntrinsics under smaller limits, values
//    still in [0, 1]; a camera one pixel wider is refused with IoError.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include <opencv2/core.hpp>

#include "colmap_io/error.h"
#include "colmap_io/image_header.h"
#include "colmap_io/image_io.h"
#include "colmap_io/sparse_model.h"
#include "tests/fuzz/fuzz_support.h"

namespace {

using dispmvs::colmap_io::Camera;
using dispmvs::colmap_io::IoError;

// The pixel limit the target reads with (the product's default is 2^28): a
// 16-byte header can claim a gigapixel image, and the limits are what keeps
// the decoders' memory bounded, so they are part of what is tested.
constexpr int64_t kMaxPixels = 262144;

// Values are in [0, 1] (area averaging may round a hair above 1).
bool ValuesInUnitRange(const cv::Mat& image) {
  if (image.type() != CV_32FC3 || image.empty()) return false;
  double min = 0, max = 0;
  cv::minMaxLoc(image.reshape(1), &min, &max);
  return min >= 0.0 && max <= 1.0 + 1e-6 && cv::checkRange(image);
}

bool SameMat(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() &&
         cv::norm(a.reshape(1), b.reshape(1), cv::NORM_INF) == 0.0;
}

Camera PinholeCamera(int width, int height) {
  Camera camera;
  camera.camera_id = 1;
  camera.model_id = 1;  // PINHOLE
  camera.width = static_cast<uint64_t>(width);
  camera.height = static_cast<uint64_t>(height);
  camera.params = {1.5 * width, 1.25 * width, 0.5 * width, 0.5 * height};
  return camera;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // OpenCV logs every file it cannot decode.
  setenv("OPENCV_LOG_LEVEL", "OFF", /*overwrite=*/0);
  // No worker threads: one input at a time.
  cv::setNumThreads(0);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = dispmvs::fuzz::ScratchPath("image");
  dispmvs::fuzz::WriteBytes(path, data, size);

  dispmvs::colmap_io::ImageLimits limits;
  limits.max_pixels = kMaxPixels;
  cv::Mat rgb;
  dispmvs::colmap_io::ImageHeader header;
  try {
    header = dispmvs::colmap_io::ReadImageHeader(
        std::string(reinterpret_cast<const char*>(data), size), path.string());
    rgb = dispmvs::colmap_io::ReadImageRgb(path, limits);
  } catch (const IoError&) {
    return 0;  // rejected cleanly: the expected outcome for most inputs
  }
  if (!ValuesInUnitRange(rgb) || rgb.cols != header.width || rgb.rows != header.height) {
    std::abort();
  }

  const Camera camera = PinholeCamera(rgb.cols, rgb.rows);
  const Eigen::Matrix3d K = camera.CalibrationMatrix();
  // The decoder is deterministic, so the second read must accept the file too.
  const auto full = dispmvs::colmap_io::ReadImageForCamera(path, camera, -1);
  if (!SameMat(full.image, rgb) || full.K != K) std::abort();

  // Half the longer side, and the extreme of a 1-pixel limit (where the
  // shorter side rounds towards 0).
  for (const int limit : {std::max(1, std::max(rgb.cols, rgb.rows) / 2), 1}) {
    const auto smaller = dispmvs::colmap_io::ReadImageForCamera(path, camera, limit);
    const cv::Size expected_size = dispmvs::colmap_io::ComputeResizedSize(rgb.size(), limit);
    if (smaller.image.size() != expected_size || !ValuesInUnitRange(smaller.image) ||
        smaller.K != dispmvs::colmap_io::ScaleIntrinsics(K, rgb.size(), expected_size)) {
      std::abort();
    }
  }

  try {
    dispmvs::colmap_io::ReadImageForCamera(path, PinholeCamera(rgb.cols + 1, rgb.rows), -1);
  } catch (const IoError&) {
    return 0;
  }
  std::abort();  // a camera of another size must be refused
}
