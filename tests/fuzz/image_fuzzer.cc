// libFuzzer target for reading a workspace image for its camera
// (ReadImageRgb, ReadImageForCamera): the input is the whole image file, in
// any format OpenCV decodes.
//
// OpenCV is linked as Debian ships it, uninstrumented: the target tests what
// the project does around the decoder (type and channel handling, the size
// check against the camera, the resize and the intrinsics), not the decoders,
// whose code gives the fuzzer no coverage feedback.
//
// Properties checked, besides "no crash, no sanitizer report, no huge
// allocation" (run with -rss_limit_mb):
//  * both functions throw nothing but IoError;
//  * an accepted image is CV_32FC3, non-empty, with every value in [0, 1];
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

#include <unistd.h>

#include <opencv2/core.hpp>

#include "colmap_io/error.h"
#include "colmap_io/image_io.h"
#include "colmap_io/sparse_model.h"
#include "tests/fuzz/fuzz_support.h"

namespace {

using dispmvs::colmap_io::Camera;
using dispmvs::colmap_io::IoError;

// Pixels above this many are refused by OpenCV's decoders (the
// OPENCV_IO_MAX_IMAGE_PIXELS setting, 2^30 by default): a 16-byte header can
// claim a gigapixel image, and decoding it would hit the fuzzer's memory
// limit inside OpenCV, which is not the code under test. OpenCV reads the
// setting while it is loaded, so it must be in the environment at start.
constexpr const char* kMaxImagePixels = "262144";

// Which decoder OpenCV will pick, from the file signature. Its code is not
// instrumented, so without these branches every format that decodes to the
// same pixel type looks the same to libFuzzer and all but one would drop out
// of its corpus; the comparisons also hand it the signatures of formats the
// seeds lack.
int FormatOf(const uint8_t* data, size_t size) {
  const auto starts = [&](const char* magic, size_t length) {
    return size >= length && std::memcmp(data, magic, length) == 0;
  };
  if (starts("\x89PNG\r\n\x1a\n", 8)) return 1;
  if (starts("\xff\xd8\xff", 3)) return 2;
  if (starts("BM", 2)) return 3;
  if (starts("II*", 4) || starts("MM\0*", 4)) return 4;
  if (starts("RIFF", 4)) return 5;  // WebP
  if (starts("P5", 2) || starts("P2", 2)) return 6;
  if (starts("P6", 2) || starts("P3", 2)) return 7;
  if (starts("P1", 2) || starts("P4", 2)) return 8;
  if (starts("P7", 2)) return 9;   // PAM
  if (starts("Pf", 2) || starts("PF", 2)) return 10;  // PFM
  if (starts("#?", 2)) return 11;  // Radiance HDR
  if (starts("\x59\xa6\x6a\x95", 4)) return 12;  // Sun raster
  if (starts("\x76\x2f\x31\x01", 4)) return 13;  // OpenEXR
  if (starts("\0\0\0\x0cjP  ", 8) || starts("\xff\x4f\xff\x51", 4)) return 14;  // JPEG 2000
  return 0;
}
// Where FormatOf's result goes, so that the optimizer keeps its branches.
volatile int format_seen = 0;

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

extern "C" int LLVMFuzzerInitialize(int*, char*** argv) {
  // OpenCV logs every file it cannot decode: most inputs.
  setenv("OPENCV_LOG_LEVEL", "OFF", /*overwrite=*/0);
  // OpenCV read the pixel limit when it was loaded (see kMaxImagePixels): run
  // again with it in the environment.
  if (std::getenv("OPENCV_IO_MAX_IMAGE_PIXELS") == nullptr) {
    setenv("OPENCV_IO_MAX_IMAGE_PIXELS", kMaxImagePixels, /*overwrite=*/1);
    execv("/proc/self/exe", *argv);
    std::abort();  // exec failed
  }
  // No worker threads: one input at a time.
  cv::setNumThreads(0);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  format_seen = FormatOf(data, size);
  const auto path = dispmvs::fuzz::ScratchPath("image");
  dispmvs::fuzz::WriteBytes(path, data, size);

  cv::Mat rgb;
  try {
    rgb = dispmvs::colmap_io::ReadImageRgb(path);
  } catch (const IoError&) {
    return 0;  // rejected cleanly: the expected outcome for most inputs
  }
  if (!ValuesInUnitRange(rgb)) std::abort();

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
