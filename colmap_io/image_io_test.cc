#include "colmap_io/image_io.h"

#include <stdexcept>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

using testing::TempDir;

void ExpectRgb(const cv::Mat& image, int row, int col, float r, float g, float b) {
  const cv::Vec3f& pixel = image.at<cv::Vec3f>(row, col);
  EXPECT_FLOAT_EQ(pixel[0], r) << "row " << row << " col " << col;
  EXPECT_FLOAT_EQ(pixel[1], g) << "row " << row << " col " << col;
  EXPECT_FLOAT_EQ(pixel[2], b) << "row " << row << " col " << col;
}

std::filesystem::path WritePng(const TempDir& dir, const std::string& name, const cv::Mat& image) {
  const auto path = dir.Make(name);
  EXPECT_TRUE(cv::imwrite(path.string(), image));
  return path;
}

TEST(ImageIoTest, Reads8BitGreyAsReplicatedRgb) {
  TempDir dir;
  cv::Mat grey(2, 3, CV_8UC1);
  const unsigned char values[6] = {0, 1, 127, 128, 254, 255};
  for (int i = 0; i < 6; ++i) grey.at<unsigned char>(i / 3, i % 3) = values[i];
  const cv::Mat rgb = ReadImageRgb(WritePng(dir, "grey8.png", grey));
  ASSERT_EQ(rgb.type(), CV_32FC3);
  ASSERT_EQ(rgb.rows, 2);
  ASSERT_EQ(rgb.cols, 3);
  for (int i = 0; i < 6; ++i) {
    const float v = values[i] / 255.0f;
    ExpectRgb(rgb, i / 3, i % 3, v, v, v);
  }
}

TEST(ImageIoTest, Reads8BitColourInRgbOrder) {
  TempDir dir;
  cv::Mat bgr(1, 2, CV_8UC3);
  bgr.at<cv::Vec3b>(0, 0) = cv::Vec3b(10, 20, 30);  // OpenCV order: B, G, R
  bgr.at<cv::Vec3b>(0, 1) = cv::Vec3b(255, 0, 128);
  const cv::Mat rgb = ReadImageRgb(WritePng(dir, "sub/colour8.png", bgr));
  ExpectRgb(rgb, 0, 0, 30 / 255.0f, 20 / 255.0f, 10 / 255.0f);
  ExpectRgb(rgb, 0, 1, 128 / 255.0f, 0.0f, 1.0f);
}

TEST(ImageIoTest, Reads16BitGreyAndColourAtFullPrecision) {
  TempDir dir;
  cv::Mat grey(1, 3, CV_16UC1);
  grey.at<uint16_t>(0, 0) = 0;
  grey.at<uint16_t>(0, 1) = 1000;  // not a multiple of 257: an 8-bit detour would lose it
  grey.at<uint16_t>(0, 2) = 65535;
  const cv::Mat grey_rgb = ReadImageRgb(WritePng(dir, "grey16.png", grey));
  ExpectRgb(grey_rgb, 0, 0, 0.0f, 0.0f, 0.0f);
  ExpectRgb(grey_rgb, 0, 1, 1000 / 65535.0f, 1000 / 65535.0f, 1000 / 65535.0f);
  ExpectRgb(grey_rgb, 0, 2, 1.0f, 1.0f, 1.0f);

  cv::Mat bgr(1, 1, CV_16UC3);
  bgr.at<cv::Vec3w>(0, 0) = cv::Vec3w(1, 300, 65534);
  const cv::Mat rgb = ReadImageRgb(WritePng(dir, "colour16.png", bgr));
  ExpectRgb(rgb, 0, 0, 65534 / 65535.0f, 300 / 65535.0f, 1 / 65535.0f);
}

TEST(ImageIoTest, DropsAlpha) {
  TempDir dir;
  cv::Mat bgra(1, 1, CV_8UC4, cv::Scalar(40, 50, 60, 0));
  const cv::Mat rgb = ReadImageRgb(WritePng(dir, "alpha.png", bgra));
  ASSERT_EQ(rgb.type(), CV_32FC3);
  ExpectRgb(rgb, 0, 0, 60 / 255.0f, 50 / 255.0f, 40 / 255.0f);
}

TEST(ImageIoTest, MissingOrCorruptFileThrowsIoErrorNamingIt) {
  TempDir dir;
  const auto missing = dir.path() / "nope.png";
  try {
    ReadImageRgb(missing);
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_EQ(e.path(), missing.string());
    EXPECT_NE(std::string(e.what()).find("nope.png"), std::string::npos);
  }
  const auto garbage = dir.Make("garbage.png");
  testing::WriteFileBytes(garbage, "this is not a PNG file at all");
  EXPECT_THROW(ReadImageRgb(garbage), IoError);
  EXPECT_THROW(ReadImageRgb(dir.path()), IoError);  // a directory
}

TEST(ImageIoTest, ResizedSizeFollowsColmapMaxImageSizeRule) {
  EXPECT_EQ(ComputeResizedSize({640, 480}, 320), cv::Size(320, 240));
  EXPECT_EQ(ComputeResizedSize({480, 640}, 320), cv::Size(240, 320));
  // factor 0.5: 333 * 0.5 = 166.5 rounds to 167.
  EXPECT_EQ(ComputeResizedSize({1000, 333}, 500), cv::Size(500, 167));
  // Not larger than the limit, or no limit: unchanged (never upscaled).
  EXPECT_EQ(ComputeResizedSize({640, 480}, 640), cv::Size(640, 480));
  EXPECT_EQ(ComputeResizedSize({640, 480}, 2000), cv::Size(640, 480));
  EXPECT_EQ(ComputeResizedSize({640, 480}, -1), cv::Size(640, 480));
  EXPECT_EQ(ComputeResizedSize({10000, 1}, 100), cv::Size(100, 1));  // never 0
  // COLMAP evaluates in float: 1000.f / 1440 = 0.69444442 (the float below
  // 0.694444...), and 702 times it rounds to the float 487.49997, so 487,
  // where exact arithmetic gives 487.5 -> 488.
  EXPECT_EQ(ComputeResizedSize({1440, 702}, 1000), cv::Size(1000, 487));
  EXPECT_THROW(ComputeResizedSize({0, 10}, 5), std::invalid_argument);
}

TEST(ImageIoTest, ScaledIntrinsicsUseEachAxisOwnFactor) {
  Eigen::Matrix3d K;
  K << 800, 0, 500.5, 0, 700, 166.25, 0, 0, 1;
  const Eigen::Matrix3d scaled = ScaleIntrinsics(K, {1000, 333}, {500, 167});
  const double sx = 0.5;
  const double sy = 167.0 / 333.0;  // differs from 0.5
  EXPECT_DOUBLE_EQ(scaled(0, 0), 800 * sx);
  EXPECT_DOUBLE_EQ(scaled(0, 2), 500.5 * sx);
  EXPECT_DOUBLE_EQ(scaled(1, 1), 700 * sy);
  EXPECT_DOUBLE_EQ(scaled(1, 2), 166.25 * sy);
  EXPECT_EQ(scaled.row(2), Eigen::RowVector3d(0, 0, 1));

  // A 3-D point lands on the same relative spot of the image before and after.
  const Eigen::Vector3d X(0.3, -0.2, 2.5);
  const Eigen::Vector3d p = K * X;
  const Eigen::Vector3d q = scaled * X;
  EXPECT_NEAR((q.x() / q.z()) / 500.0, (p.x() / p.z()) / 1000.0, 1e-12);
  EXPECT_NEAR((q.y() / q.z()) / 167.0, (p.y() / p.z()) / 333.0, 1e-12);
}

// A float image whose channel 0 holds each pixel centre's relative x position
// (col + 0.5) / width and channel 1 the relative y position: a sampled ramp.
cv::Mat RelativePositionImage(int width, int height) {
  cv::Mat image(height, width, CV_32FC3);
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      image.at<cv::Vec3f>(row, col) =
          cv::Vec3f((col + 0.5f) / width, (row + 0.5f) / height, 0.25f);
    }
  }
  return image;
}

// Checks, independently of ScaleIntrinsics, that resizing maps continuous
// coordinates x -> s * x with pixel centres at +0.5 (the convention the
// intrinsics are scaled under): resized pixel (col, row) averages the source
// over its footprint, whose centre has relative position (col + 0.5) / new
// width. The source is a staircase, not a line: over a footprint of 1/s
// source pixels the average of the (zero-mean, +-0.5 px) staircase error is at
// most (1/8) / (1/s) source pixels, which is the tolerance (plus float noise).
// For integer factors footprints cover whole pixels and the match is exact.
// Sampling at s * index instead (no half-pixel convention) would be off by
// 0.5 * (1/s - 1) source pixels.
void ExpectRampResizedCorrectly(const cv::Mat& resized, int old_width, int old_height) {
  const double tolerance_x = (1.0 / 8.0) * resized.cols / old_width / old_width + 2e-6;
  const double tolerance_y = (1.0 / 8.0) * resized.rows / old_height / old_height + 2e-6;
  for (int row = 0; row < resized.rows; ++row) {
    for (int col = 0; col < resized.cols; ++col) {
      const cv::Vec3f& pixel = resized.at<cv::Vec3f>(row, col);
      ASSERT_NEAR(pixel[0], (col + 0.5) / resized.cols, tolerance_x) << row << "," << col;
      ASSERT_NEAR(pixel[1], (row + 0.5) / resized.rows, tolerance_y) << row << "," << col;
      ASSERT_NEAR(pixel[2], 0.25, 1e-6);
    }
  }
}

TEST(ImageIoTest, IntegerDownscaleKeepsPixelCentresExactly) {
  const cv::Mat image = RelativePositionImage(640, 480);
  const ResizedImage resized = ResizeToMaxImageSize(image, Eigen::Matrix3d::Identity(), 160);
  ASSERT_EQ(resized.image.size(), cv::Size(160, 120));
  for (int row = 0; row < 120; ++row) {
    for (int col = 0; col < 160; ++col) {
      const cv::Vec3f& pixel = resized.image.at<cv::Vec3f>(row, col);
      ASSERT_NEAR(pixel[0], (col + 0.5) / 160.0, 1e-6) << row << "," << col;
      ASSERT_NEAR(pixel[1], (row + 0.5) / 120.0, 1e-6) << row << "," << col;
    }
  }
}

TEST(ImageIoTest, ResizeMovesContentConsistentlyWithScaledIntrinsics) {
  Eigen::Matrix3d K;
  K << 500, 0, 320, 0, 480, 240, 0, 0, 1;
  const cv::Mat image = RelativePositionImage(640, 480);
  const ResizedImage resized = ResizeToMaxImageSize(image, K, 500);  // factor 0.78125
  ASSERT_EQ(resized.image.size(), cv::Size(500, 375));
  ExpectRampResizedCorrectly(resized.image, 640, 480);

  // The pixel the scaled K projects a point into holds the relative position
  // the original K gives it, to within half a resized pixel (the pixel's
  // value is its centre's position) plus the staircase tolerance.
  const Eigen::Vector3d X(0.4, 0.1, 3.0);
  const Eigen::Vector3d p = K * X;
  const Eigen::Vector3d q = resized.K * X;
  const int col = static_cast<int>(q.x() / q.z());
  const int row = static_cast<int>(q.y() / q.z());
  EXPECT_NEAR(resized.image.at<cv::Vec3f>(row, col)[0], (p.x() / p.z()) / 640.0,
              0.5 / 500.0 + 0.125 / 640.0);
  EXPECT_NEAR(resized.image.at<cv::Vec3f>(row, col)[1], (p.y() / p.z()) / 480.0,
              0.5 / 375.0 + 0.125 / 480.0);
}

TEST(ImageIoTest, DownscalingAveragesAreas) {
  // One lit pixel per 4x4 block: area averaging gives 1/16 everywhere, while
  // point sampling (nearest or bilinear at these positions) would give 0 or 1.
  cv::Mat image(8, 8, CV_32FC3, cv::Scalar::all(0));
  for (int row = 0; row < 8; row += 4) {
    for (int col = 0; col < 8; col += 4) image.at<cv::Vec3f>(row, col) = cv::Vec3f(1, 1, 1);
  }
  const ResizedImage resized = ResizeToMaxImageSize(image, Eigen::Matrix3d::Identity(), 2);
  ASSERT_EQ(resized.image.size(), cv::Size(2, 2));
  for (int row = 0; row < 2; ++row) {
    for (int col = 0; col < 2; ++col) {
      ExpectRgb(resized.image, row, col, 1 / 16.f, 1 / 16.f, 1 / 16.f);
    }
  }
  EXPECT_DOUBLE_EQ(resized.K(0, 0), 0.25);
}

TEST(ImageIoTest, NoResizeReturnsAnIndependentCopy) {
  const cv::Mat image(4, 4, CV_32FC3, cv::Scalar::all(0.5));
  Eigen::Matrix3d K;
  K << 3, 0, 2, 0, 3, 2, 0, 0, 1;
  const ResizedImage resized = ResizeToMaxImageSize(image, K, -1);
  EXPECT_EQ(resized.image.size(), image.size());
  EXPECT_NE(resized.image.data, image.data);
  EXPECT_EQ(resized.K, K);
}

TEST(ImageIoTest, ReadImageForCameraChecksSizeAndScales) {
  TempDir dir;
  const auto path = WritePng(dir, "img.png", cv::Mat(240, 320, CV_8UC3, cv::Scalar(1, 2, 3)));
  Camera camera;
  camera.camera_id = 3;
  camera.model_id = 1;  // PINHOLE
  camera.width = 320;
  camera.height = 240;
  camera.params = {300, 310, 160, 120};
  const ResizedImage resized = ReadImageForCamera(path, camera, 160);
  EXPECT_EQ(resized.image.size(), cv::Size(160, 120));
  EXPECT_EQ(resized.image.type(), CV_32FC3);
  EXPECT_DOUBLE_EQ(resized.K(0, 0), 150);
  EXPECT_DOUBLE_EQ(resized.K(1, 1), 155);
  EXPECT_DOUBLE_EQ(resized.K(0, 2), 80);
  EXPECT_DOUBLE_EQ(resized.K(1, 2), 60);

  camera.width = 321;
  try {
    ReadImageForCamera(path, camera, -1);
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_EQ(e.path(), path.string());
  }
}

TEST(ImageIoTest, PixelIndexConventionShiftsPrincipalPointByHalfAPixel) {
  Eigen::Matrix3d K;
  K << 300, 0, 160, 0, 310, 120, 0, 0, 1;
  const Eigen::Matrix3d K_index = ToPixelIndexConvention(K);
  EXPECT_EQ(K_index(0, 0), 300);
  EXPECT_EQ(K_index(1, 1), 310);
  // A ray through the centre of the top-left pixel: (0.5, 0.5) in COLMAP's
  // convention must become index (0, 0).
  const Eigen::Vector3d ray = K.inverse() * Eigen::Vector3d(0.5, 0.5, 1.0);
  const Eigen::Vector3d index = K_index * ray;
  EXPECT_NEAR(index.x() / index.z(), 0.0, 1e-12);
  EXPECT_NEAR(index.y() / index.z(), 0.0, 1e-12);
}

// A linear ramp v = a x + b y + c over COLMAP's continuous coordinates (pixel
// (col, row) covers [col, col+1) x [row, row+1), its mean is the value at the
// centre). After resampling, pixel (col, row) must hold the ramp at (col, row)
// of the resized image, away from the replicated border.
TEST(ImageIoTest, DenseIndexGridHoldsColoursAtIntegerPositions) {
  const double a = 0.01, b = 0.004, c = 0.1;
  cv::Mat ramp(48, 64, CV_32FC3);
  for (int row = 0; row < ramp.rows; ++row) {
    for (int col = 0; col < ramp.cols; ++col) {
      const float v = static_cast<float>(a * (col + 0.5) + b * (row + 0.5) + c);
      ramp.at<cv::Vec3f>(row, col) = cv::Vec3f(v, 2 * v, 0.5f * v);
    }
  }
  Eigen::Matrix3d K;
  K << 50, 0, 32, 0, 50, 24, 0, 0, 1;
  for (const cv::Size size : {cv::Size(64, 48), cv::Size(32, 24), cv::Size(16, 12)}) {
    const ResizedImage result = ResampleToDenseIndexGrid(ramp, K, size);
    ASSERT_EQ(result.image.size(), size);
    const double s = static_cast<double>(size.width) / ramp.cols;
    EXPECT_DOUBLE_EQ(result.K(0, 2), 32 * s);
    EXPECT_DOUBLE_EQ(result.K(0, 0), 50 * s);
    for (int row = 1; row < size.height; ++row) {
      for (int col = 1; col < size.width; ++col) {
        // Continuous (col, row) of the resized image is (col, row) / s of the original.
        const double expected = a * col / s + b * row / s + c;
        const cv::Vec3f got = result.image.at<cv::Vec3f>(row, col);
        ASSERT_NEAR(got[0], expected, 1e-5) << size << " " << row << " " << col;
        ASSERT_NEAR(got[1], 2 * expected, 2e-5);
      }
    }
  }
  EXPECT_THROW(ResampleToDenseIndexGrid(cv::Mat(), K, cv::Size(4, 4)), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::colmap_io
