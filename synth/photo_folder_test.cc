// Loading a folder of photographs for photo textures (the full build, with
// OpenCV: every format; PPM/PGM through the project's own reader).

#include "synth/photo_folder.h"

#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "tests/support/temp_dir.h"

namespace dispmvs::synth {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

TEST(PhotoFolderTest, LoadsDecodableImagesInNameOrderAsRgb) {
  ASSERT_TRUE(PhotoFolderDecodesAllFormats());
  TempDir tmp;
  // b_red.png: pure red (BGR 0,0,255); a_wide.jpg: 1000x300, shrunk to 512 wide.
  cv::imwrite((tmp.path() / "b_red.png").string(), cv::Mat(20, 40, CV_8UC3, cv::Scalar(0, 0, 255)));
  cv::Mat wide(300, 1000, CV_8UC3, cv::Scalar(200, 100, 50));
  cv::imwrite((tmp.path() / "a_wide.JPG").string(), wide);
  cv::imwrite((tmp.path() / "c_tiny.png").string(), cv::Mat(8, 8, CV_8UC3, cv::Scalar(1, 2, 3)));
  std::ofstream(tmp.path() / "d_broken.png") << "not a png";
  std::ofstream(tmp.path() / "notes.txt") << "ignored";
  fs::create_directories(tmp.path() / "sub.png");  // a folder is not a photo

  std::ostringstream warnings;
  const PhotoSet photos = LoadPhotoFolder(tmp.path().string(), {}, &warnings);
  ASSERT_EQ(photos.size(), 2u);
  CheckPhotoSet(photos);
  // 300 * 512 / 1000 = 153.6 -> 154 rows.
  EXPECT_EQ(photos[0].sizes(), torch::IntArrayRef({3, 154, 512}));
  // JPEG is lossy: within a few levels of RGB (50, 100, 200) / 255.
  EXPECT_NEAR(photos[0][0].mean().item<double>(), 50 / 255.0, 0.02);
  EXPECT_NEAR(photos[0][2].mean().item<double>(), 200 / 255.0, 0.02);
  EXPECT_EQ(photos[1].sizes(), torch::IntArrayRef({3, 20, 40}));
  EXPECT_EQ(photos[1][0].min().item<float>(), 1.0f);
  EXPECT_EQ(photos[1].narrow(0, 1, 2).max().item<float>(), 0.0f);
  EXPECT_NE(warnings.str().find("c_tiny.png is smaller than 16 pixels"), std::string::npos) << warnings.str();
  EXPECT_NE(warnings.str().find("cannot decode"), std::string::npos) << warnings.str();
  EXPECT_NE(warnings.str().find("d_broken.png"), std::string::npos) << warnings.str();

  PhotoFolderOptions one;
  one.max_photos = 1;
  EXPECT_EQ(LoadPhotoFolder(tmp.path().string(), one).size(), 1u);
}

TEST(PhotoFolderTest, PpmPhotosAreShrunkByAreaAveraging) {
  TempDir tmp;
  // 1000 x 300, left half RGB (200, 100, 50), right half (0, 0, 0): shrunk to
  // 512 x 154 by area averaging, the mean keeps half the colour.
  std::string pixels;
  for (int y = 0; y < 300; ++y) {
    for (int x = 0; x < 1000; ++x) pixels += x < 500 ? std::string{'\xc8', '\x64', '\x32'} : std::string(3, '\0');
  }
  std::ofstream(tmp.path() / "wide.PPM", std::ios::binary) << "P6\n1000 300\n255\n" << pixels;
  std::ofstream(tmp.path() / "cut.ppm", std::ios::binary) << "P6\n1000 300\n255\n" << pixels.substr(0, 99);
  std::ostringstream warnings;
  const PhotoSet photos = LoadPhotoFolder(tmp.path().string(), {}, &warnings);
  ASSERT_EQ(photos.size(), 1u);
  EXPECT_EQ(photos[0].sizes(), torch::IntArrayRef({3, 154, 512}));
  EXPECT_NEAR(photos[0][0].mean().item<double>(), 0.5 * 200 / 255.0, 1e-3);
  EXPECT_NEAR(photos[0][2].mean().item<double>(), 0.5 * 50 / 255.0, 1e-3);
  EXPECT_FLOAT_EQ(photos[0][0][77][0].item<float>(), 200 / 255.0f);
  EXPECT_FLOAT_EQ(photos[0][1][77][511].item<float>(), 0.0f);
  EXPECT_NE(warnings.str().find("cut.ppm: truncated"), std::string::npos) << warnings.str();
}

TEST(PhotoFolderTest, MissingOrUselessFoldersAreRefused) {
  TempDir tmp;
  EXPECT_THROW(LoadPhotoFolder((tmp.path() / "nothing").string()), std::invalid_argument);
  std::ofstream(tmp.path() / "broken.jpg") << "garbage";
  try {
    LoadPhotoFolder(tmp.path().string());
    FAIL() << "expected a refusal";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("no usable photo (1 image files)"), std::string::npos) << e.what();
  }
  PhotoFolderOptions bad;
  bad.max_photos = 0;
  EXPECT_THROW(LoadPhotoFolder(tmp.path().string(), bad), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::synth
