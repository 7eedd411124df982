#include "colmap_io/image_io.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>
#include <system_error>

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "colmap_io/error.h"
#include "colmap_io/image_header.h"

namespace dispmvs::colmap_io {
namespace {

std::string SizeToString(const cv::Size& size) {
  return std::to_string(size.width) + "x" + std::to_string(size.height);
}

void CheckSize(const cv::Size& size, const char* what) {
  if (size.width < 1 || size.height < 1) {
    throw std::invalid_argument(std::string(what) + ": image size must be positive, got " +
                                SizeToString(size));
  }
}

// The whole file, refused unread when it is larger than `max_bytes`.
std::string ReadFileBytes(const std::filesystem::path& path, uint64_t max_bytes) {
  std::error_code error;
  const uint64_t size = std::filesystem::file_size(path, error);
  if (error) throw IoError(path.string(), "cannot read image file: " + error.message());
  if (size > max_bytes) {
    throw IoError(path.string(), "image file of " + std::to_string(size) +
                                     " bytes is larger than any image of its allowed size (" +
                                     std::to_string(max_bytes) + " bytes at most)");
  }
  std::ifstream in(path, std::ios::binary);
  std::string bytes(size, '\0');
  if (!in.read(bytes.data(), static_cast<std::streamsize>(size))) {
    throw IoError(path.string(), "cannot read image file");
  }
  return bytes;
}

// Bytes allowed for `pixels` pixels: 16-bit RGBA is 8 bytes per pixel; twice
// that leaves room for whatever a format stores beside the pixels, and
// 64 MiB for metadata (EXIF thumbnails, XMP) of small images.
uint64_t AllowedBytes(int64_t pixels) { return 16 * static_cast<uint64_t>(pixels) + (64u << 20); }

}  // namespace

cv::Mat ReadImageRgb(const std::filesystem::path& path, const ImageLimits& limits) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    throw IoError(path.string(), "image file does not exist");
  }
  const int64_t allowed_pixels =
      limits.expected_size
          ? static_cast<int64_t>(limits.expected_size->width) * limits.expected_size->height
          : limits.max_pixels;
  // OpenCV takes the encoded bytes as one row of int columns.
  const std::string bytes = ReadFileBytes(
      path, std::min<uint64_t>(AllowedBytes(allowed_pixels), std::numeric_limits<int>::max()));
  const ImageHeader header = ReadImageHeader(bytes, path.string());
  const cv::Size size(header.width, header.height);
  if (limits.expected_size && size != *limits.expected_size) {
    throw IoError(path.string(), "image is " + SizeToString(size) + " but " +
                                     limits.expected_size_of + " is " +
                                     SizeToString(*limits.expected_size) +
                                     (limits.size_mismatch_hint.empty()
                                          ? ""
                                          : " (" + limits.size_mismatch_hint + ")"));
  }
  if (static_cast<int64_t>(header.width) * header.height > allowed_pixels) {
    throw IoError(path.string(), "image of " + SizeToString(size) + " is larger than " +
                                     std::to_string(allowed_pixels) + " pixels");
  }
  // Against the image's own size: its pixels may well fit the limits while a
  // damaged header makes the decoder's buffer a thousand times larger.
  if (header.decoder_buffer_bytes >
      AllowedBytes(static_cast<int64_t>(header.width) * header.height)) {
    throw IoError(path.string(),
                  std::string(ImageFormatName(header.format)) + " header asks the decoder for a " +
                      std::to_string(header.decoder_buffer_bytes >> 20) +
                      " MiB buffer for a " + SizeToString(size) +
                      " image (damaged strip or tile sizes)");
  }

  // OpenCV logs a decoder's failure to stderr; the IoError below says it
  // once, with the file's name, in the program's own words. Process-wide:
  // nothing else in the project relies on OpenCV's log.
  static const bool silenced = [] {
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    return true;
  }();
  (void)silenced;
  // IMREAD_UNCHANGED keeps 16-bit data and the channel count as stored
  // (IMREAD_COLOR would silently reduce 16-bit images to 8 bits).
  const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8UC1,
                        const_cast<char*>(bytes.data()));
  cv::Mat raw;
  try {
    raw = cv::imdecode(encoded, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw IoError(path.string(), std::string("cannot decode ") + ImageFormatName(header.format) +
                                     " image: " + e.what());
  }
  if (raw.empty()) {
    throw IoError(path.string(), std::string("cannot decode ") + ImageFormatName(header.format) +
                                     " image (damaged or truncated file)");
  }
  if (raw.size() != size) {  // the decoder and the header disagree: trust neither
    throw IoError(path.string(), std::string(ImageFormatName(header.format)) + " header says " +
                                     SizeToString(size) + " but the decoder read " +
                                     SizeToString(raw.size()) + " (damaged file)");
  }

  double scale = 0.0;
  switch (raw.depth()) {
    case CV_8U: scale = 1.0 / 255.0; break;
    case CV_16U: scale = 1.0 / 65535.0; break;
    default:
      throw IoError(path.string(), "unsupported pixel type (only 8-bit and 16-bit images)");
  }

  // OpenCV stores colour as BGR(A).
  cv::Mat rgb;
  switch (raw.channels()) {
    case 1: cv::cvtColor(raw, rgb, cv::COLOR_GRAY2RGB); break;
    case 3: cv::cvtColor(raw, rgb, cv::COLOR_BGR2RGB); break;
    case 4: cv::cvtColor(raw, rgb, cv::COLOR_BGRA2RGB); break;
    default:
      throw IoError(path.string(),
                    "unsupported channel count " + std::to_string(raw.channels()));
  }
  cv::Mat result;
  rgb.convertTo(result, CV_32FC3, scale);
  return result;
}

cv::Size ComputeResizedSize(const cv::Size& size, int max_image_size) {
  CheckSize(size, "ComputeResizedSize");
  if (max_image_size <= 0 ||
      (size.width <= max_image_size && size.height <= max_image_size)) {
    return size;
  }
  // Single precision on purpose: COLMAP computes the factor and the products
  // in float, and double precision gives a different size now and then (1440 x
  // 702 at 1000: COLMAP 1000 x 487, double 1000 x 488). Same sizes as COLMAP
  // let our maps be compared with PatchMatch's pixel for pixel.
  const float limit = static_cast<float>(max_image_size);
  const float factor = std::min(limit / static_cast<float>(size.width),
                                limit / static_cast<float>(size.height));
  const auto scaled_side = [factor](int side) {
    const float scaled = std::round(static_cast<float>(side) * factor);
    return std::max(1, static_cast<int>(scaled));  // never 0 for extreme aspect ratios
  };
  return {scaled_side(size.width), scaled_side(size.height)};
}

Eigen::Matrix3d ScaleIntrinsics(const Eigen::Matrix3d& K, const cv::Size& old_size,
                                const cv::Size& new_size) {
  CheckSize(old_size, "ScaleIntrinsics");
  CheckSize(new_size, "ScaleIntrinsics");
  const double scale_x = static_cast<double>(new_size.width) / old_size.width;
  const double scale_y = static_cast<double>(new_size.height) / old_size.height;
  Eigen::Matrix3d scaled = K;
  scaled.row(0) *= scale_x;
  scaled.row(1) *= scale_y;
  return scaled;
}

ResizedImage ResizeToMaxImageSize(const cv::Mat& image, const Eigen::Matrix3d& K,
                                  int max_image_size) {
  if (image.empty()) throw std::invalid_argument("ResizeToMaxImageSize: empty image");
  const cv::Size new_size = ComputeResizedSize(image.size(), max_image_size);
  ResizedImage result;
  if (new_size == image.size()) {
    result.image = image.clone();
    result.K = K;
    return result;
  }
  cv::resize(image, result.image, new_size, 0.0, 0.0, cv::INTER_AREA);
  result.K = ScaleIntrinsics(K, image.size(), new_size);
  return result;
}

ImageLimits ImageLimitsForCamera(const std::filesystem::path& path, const Camera& camera) {
  if (camera.width < 1 || camera.height < 1 || camera.width > (1u << 24) ||
      camera.height > (1u << 24)) {
    throw IoError(path.string(), "camera " + std::to_string(camera.camera_id) + " has size " +
                                     std::to_string(camera.width) + "x" +
                                     std::to_string(camera.height) + ", no image can match it");
  }
  ImageLimits limits;
  limits.expected_size = cv::Size(static_cast<int>(camera.width), static_cast<int>(camera.height));
  limits.expected_size_of = "camera " + std::to_string(camera.camera_id);
  return limits;
}

ResizedImage ReadImageForCamera(const std::filesystem::path& path, const Camera& camera,
                                int max_image_size) {
  const Eigen::Matrix3d K = camera.CalibrationMatrix();
  ImageLimits limits = ImageLimitsForCamera(path, camera);
  limits.size_mismatch_hint = "dense MVS needs the undistorted images";
  return ResizeToMaxImageSize(ReadImageRgb(path, limits), K, max_image_size);
}

ResizedImage ResampleToDenseIndexGrid(const cv::Mat& image, const Eigen::Matrix3d& K,
                                      const cv::Size& size) {
  if (image.empty() || size.width < 1 || size.height < 1) {
    throw std::invalid_argument("ResampleToDenseIndexGrid: empty image or size");
  }
  cv::Mat resized;
  if (size == image.size()) {
    resized = image;
  } else {
    const bool shrinking = size.width <= image.cols && size.height <= image.rows;
    cv::resize(image, resized, size, 0.0, 0.0, shrinking ? cv::INTER_AREA : cv::INTER_LINEAR);
  }
  // OpenCV samples at integer pixel centres; the inverse map reads the
  // source at (col - 0.5, row - 0.5), which is continuous position (col, row)
  // in COLMAP's convention.
  const cv::Matx23d shift(1.0, 0.0, -0.5, 0.0, 1.0, -0.5);
  ResizedImage result;
  cv::warpAffine(resized, result.image, shift, size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                 cv::BORDER_REPLICATE);
  result.K = ScaleIntrinsics(K, image.size(), size);
  return result;
}

Eigen::Matrix3d ToPixelIndexConvention(const Eigen::Matrix3d& K_colmap) {
  Eigen::Matrix3d K = K_colmap;
  K(0, 2) -= 0.5;
  K(1, 2) -= 0.5;
  return K;
}

}  // namespace dispmvs::colmap_io
