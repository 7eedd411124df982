#pragma once
// Loading the workspace's undistorted images for the network, and resizing
// them under COLMAP's `max_image_size` rule with intrinsics that stay exact.
//
// Pixel conventions. COLMAP's intrinsics put the centre of the top-left pixel
// at (0.5, 0.5): pixel (col, row) covers [col, col+1) x [row, row+1). Resizing
// an image by a factor s per axis maps every continuous coordinate x to s * x,
// so fx and cx scale by s_x = new_width / old_width and fy and cy by
// s_y = new_height / old_height. Because sizes are rounded, s_x and s_y
// differ slightly and each axis uses its own. A network that samples at
// integer pixel indices (pixel (col, row) at coordinate (col, row), e.g.
// grid_sample with align_corners=true over index grids) needs the principal
// point shifted by -0.5: see ToPixelIndexConvention().

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "colmap_io/sparse_model.h"

namespace dispmvs::colmap_io {

// What an image may be before it is decoded (see image_header.h for why the
// header is read first).
struct ImageLimits {
  // The size the image must have (the camera's), checked on the header before
  // any pixel is allocated; std::nullopt: any size up to max_pixels.
  std::optional<cv::Size> expected_size;
  // What expected_size is, for the message (e.g. "camera 3").
  std::string expected_size_of = "the expected size";
  // Said in parentheses after a wrong size, when not empty.
  std::string size_mismatch_hint;
  // Refused above this many pixels when no size is expected (2^28: 16384^2;
  // OpenCV's own limit is 2^30).
  int64_t max_pixels = int64_t{1} << 28;
};

// Reads an image and returns it as CV_32FC3 in RGB channel order with values
// in [0, 1]: 8-bit data is divided by 255, 16-bit data by 65535; grey images
// are replicated to three channels and an alpha channel is dropped.
//
// The file is read into memory, its format and size are taken from its header
// (ReadImageHeader: PNG, JPEG, TIFF, BMP, PNM or WebP, nothing else reaches a
// decoder), checked against `limits` together with the file's size and the
// decoder's own buffer, and only then decoded by that format's OpenCV decoder
// (cv::imdecode). Memory stays bounded by the limits: at most 16 bytes per
// allowed pixel plus 64 MiB for the file, and the same for a TIFF's strip or
// tile buffer. Throws IoError naming `path` and the reason when the file is
// missing, of another format, damaged or truncated, of another size than
// expected, too large, or of another bit depth or channel count.
cv::Mat ReadImageRgb(const std::filesystem::path& path, const ImageLimits& limits = {});

// COLMAP's max_image_size rule (mvs::Image::Downsize): unchanged when both
// sides are <= max_image_size or when max_image_size <= 0 (COLMAP's -1 means
// no limit); otherwise factor = min(max/width, max/height) and each side
// becomes round(side * factor), evaluated in single precision exactly as
// COLMAP does so that the sizes match its maps. Throws std::invalid_argument
// for sizes < 1.
cv::Size ComputeResizedSize(const cv::Size& size, int max_image_size);

// Intrinsics (COLMAP convention) of an image resized from `old_size` to
// `new_size`: fx, cx scaled by new.width/old.width, fy, cy by
// new.height/old.height. Only fx, fy, cx, cy (and skew, by s_x) are used;
// the last row stays (0, 0, 1). Throws std::invalid_argument for empty sizes.
Eigen::Matrix3d ScaleIntrinsics(const Eigen::Matrix3d& K, const cv::Size& old_size,
                                const cv::Size& new_size);

struct ResizedImage {
  cv::Mat image;      // same type as the input
  Eigen::Matrix3d K;  // COLMAP convention, matching `image`
};

// Resizes `image` to ComputeResizedSize(image.size(), max_image_size) and
// scales K to match. Downscaling uses area interpolation (each output pixel
// the mean of the input area it covers, so no aliasing); upscaling never
// happens under this rule. Returns a copy sharing no data with the input
// when the size is unchanged as well.
ResizedImage ResizeToMaxImageSize(const cv::Mat& image, const Eigen::Matrix3d& K,
                                  int max_image_size);

// The limits of an image taken with `camera`: its size expected, said as
// "camera ID" in a message. Throws IoError naming `path` for a camera whose
// size no image can have (0, or a side above 2^24).
ImageLimits ImageLimitsForCamera(const std::filesystem::path& path, const Camera& camera);

// ReadImageRgb with the camera's size as the expected size (dense MVS needs
// undistorted images matching their camera: IoError naming `path` otherwise,
// before the pixels are decoded) + ResizeToMaxImageSize with
// camera.CalibrationMatrix() (which throws std::invalid_argument for
// non-pinhole cameras).
ResizedImage ReadImageForCamera(const std::filesystem::path& path, const Camera& camera,
                                int max_image_size);

// `image` (intrinsics K, COLMAP convention) brought to `size` and resampled
// onto COLMAP's dense index grid: pixel (col, row) of the result holds the
// colour at continuous position (col, row) of the resized image, i.e. half a
// pixel up and left of that pixel's centre (bilinear, border replicated).
// With this resampling the returned K (COLMAP's, scaled to `size`) is the
// exact intrinsics of the result in the pixel-index convention, so a network
// that treats pixel (col, row) as the ray K^-1 (col, row, 1) both matches
// with exact geometry and produces depth maps in the indexing COLMAP's
// PatchMatch and stereo_fusion use, without resampling the depth afterwards.
// Downscaling first averages areas (no aliasing), as ResizeToMaxImageSize.
// Throws std::invalid_argument for an empty image or size.
ResizedImage ResampleToDenseIndexGrid(const cv::Mat& image, const Eigen::Matrix3d& K,
                                      const cv::Size& size);

// COLMAP intrinsics -> intrinsics for pixel-index coordinates, where pixel
// (col, row) sits at (col, row) instead of (col + 0.5, row + 0.5): cx - 0.5 and
// cy - 0.5, focal lengths unchanged. Apply it AFTER any scaling (the shift is
// half a pixel of the final image, it does not scale).
//
// Beware: COLMAP's own dense stage does NOT make this shift. PatchMatch and
// stereo_fusion (colmap/mvs/fusion.cc back-projects depth-map pixel (col, row)
// as K^-1 (col, row, 1) * depth) use the sparse model's K with raw pixel
// indices. A depth map sampled exactly at pixel centres is therefore fused by
// COLMAP half a pixel off: on the example workspace (examples/), exact
// pixel-centre depth fused by colmap 3.8 stereo_fusion lies a median 7.5e-3
// scene units (p99 1.9e-2, at depths 3 to 10) off the true surfaces, versus
// 6e-8 when the maps are sampled at (col, row). Maps meant for COLMAP's
// fusion must follow COLMAP's indexing.
Eigen::Matrix3d ToPixelIndexConvention(const Eigen::Matrix3d& K_colmap);

}  // namespace dispmvs::colmap_io
