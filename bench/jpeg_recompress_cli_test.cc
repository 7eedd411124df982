// dispmvs_jpeg_recompress on generated images: each file replaced in its own
// format by libjpeg's round trip at the quality, and bad input refused with
// one "error: " line and the files untouched.

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tests/support/run_program.h"
#include "tests/support/temp_dir.h"

#ifndef DISPMVS_JPEG_RECOMPRESS_PROGRAM
#error "DISPMVS_JPEG_RECOMPRESS_PROGRAM must name the dispmvs_jpeg_recompress binary"
#endif

namespace dispmvs::bench {
namespace {

using dispmvs::testing::ExpectError;
using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::RunProgram;
using dispmvs::testing::TempDir;

constexpr const char* kProgram = DISPMVS_JPEG_RECOMPRESS_PROGRAM;

cv::Mat Card(int type) {
  cv::Mat image(40, 56, type);
  cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));
  return image;
}

cv::Mat LibjpegRoundTrip(const cv::Mat& image, int quality) {
  std::vector<uchar> bytes;
  EXPECT_TRUE(cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, quality}));
  return cv::imdecode(bytes, image.channels() == 1 ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
}

TEST(JpegRecompressCliTest, ReplacesEachImageByItsJpegRoundTripInItsFormat) {
  TempDir tmp;
  const cv::Mat colour = Card(CV_8UC3), grey = Card(CV_8UC1);
  const std::string colour_png = (tmp.path() / "a.png").string(), grey_png = (tmp.path() / "b.png").string();
  ASSERT_TRUE(cv::imwrite(colour_png, colour));
  ASSERT_TRUE(cv::imwrite(grey_png, grey));
  const auto run = RunProgram(tmp, kProgram, "--quality 40 --images '" + colour_png + "' '" + grey_png + "'");
  ASSERT_EQ(run.status, 0) << run.err;
  EXPECT_EQ(ReadFileBytes(colour_png).substr(1, 3), "PNG");  // still a PNG file
  const cv::Mat colour_after = cv::imread(colour_png, cv::IMREAD_UNCHANGED);
  const cv::Mat grey_after = cv::imread(grey_png, cv::IMREAD_UNCHANGED);
  ASSERT_EQ(colour_after.type(), CV_8UC3);
  ASSERT_EQ(grey_after.type(), CV_8UC1);
  EXPECT_EQ(cv::norm(colour_after, LibjpegRoundTrip(colour, 40), cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(grey_after, LibjpegRoundTrip(grey, 40), cv::NORM_INF), 0);
  EXPECT_GT(cv::norm(colour_after, colour, cv::NORM_L1) / colour.total(), 10.0);  // noise does not survive q40
}

TEST(JpegRecompressCliTest, RefusesBadInputAndLeavesFilesAlone) {
  TempDir tmp;
  const std::string png = (tmp.path() / "a.png").string();
  ASSERT_TRUE(cv::imwrite(png, Card(CV_8UC3)));
  const std::string before = ReadFileBytes(png);
  ExpectError(RunProgram(tmp, kProgram, "--quality 0 --images '" + png + "'"), "--quality must be given, in [1, 100]");
  ExpectError(RunProgram(tmp, kProgram, "--quality high --images '" + png + "'"), "quality");
  ExpectError(RunProgram(tmp, kProgram, "--quality 80"), "--images must name at least one file");
  ExpectError(RunProgram(tmp, kProgram, "--quality 80 --images '" + (tmp.path() / "missing.png").string() + "'"), "cannot read an image");
  const cv::Mat deep(8, 8, CV_16UC1, cv::Scalar(1000));
  const std::string deep_png = (tmp.path() / "deep.png").string();
  ASSERT_TRUE(cv::imwrite(deep_png, deep));
  ExpectError(RunProgram(tmp, kProgram, "--quality 80 --images '" + deep_png + "'"), "only 8-bit");
  EXPECT_EQ(ReadFileBytes(png), before);
  const auto help = RunProgram(tmp, kProgram, "--help");
  EXPECT_EQ(help.status, 0);
  EXPECT_NE(help.out.find("Usage: dispmvs_jpeg_recompress --quality Q --images FILE..."), std::string::npos);
}

}  // namespace
}  // namespace dispmvs::bench
