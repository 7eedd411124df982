#include "eval/cloud_render.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <stdexcept>
#include <vector>

namespace dispmvs::eval {
namespace {

colmap_io::PlyPoint Point(double x, double y, double z, uint8_t red) {
  colmap_io::PlyPoint p;
  p.xyz = {static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
  p.rgb = {red, 200, 50};
  return p;
}

// Pixels that are not the background.
double DrawnShare(const cv::Mat& image) {
  int drawn = 0;
  for (int r = 0; r < image.rows; ++r) {
    for (int c = 0; c < image.cols; ++c) {
      if (image.at<cv::Vec3b>(r, c) != cv::Vec3b(40, 40, 40)) ++drawn;
    }
  }
  return static_cast<double>(drawn) / (static_cast<double>(image.rows) * image.cols);
}

// A square of side 10 on the plane z = 0 (plus a little relief), sampled on
// an n x n grid.
std::vector<colmap_io::PlyPoint> Ground(int n) {
  std::vector<colmap_io::PlyPoint> points;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const double x = -5 + 10.0 * i / (n - 1), y = -5 + 10.0 * j / (n - 1);
      points.push_back(Point(x, y, 0.05 * x, 120));
    }
  }
  return points;
}

// A real capture's cloud: the dense part plus a few far points (sky, stray
// matches) thousands of times further away. The top view must show the
// dense part over most of the picture, not in a few pixels.
TEST(CloudRenderTest, FarOutliersDoNotShrinkTheDensePart) {
  std::vector<colmap_io::PlyPoint> points = Ground(300);  // 90,000 points
  for (int k = 0; k < 300; ++k) {  // 0.3 %, up to 10^4 away in every direction
    const double s = 1e4 * (k % 2 == 0 ? 1 : -1);
    points.push_back(Point(s * ((k % 7) - 3), s * ((k % 5) - 2), s * ((k % 3) - 1), 255));
  }
  const std::vector<cv::Mat> views = RenderCloudViews(points, 200);
  ASSERT_EQ(views.size(), 3u);
  // The square fills the 1st-99th percentile extent, 90 % of the picture's
  // side: about 0.78 of its area.
  EXPECT_GT(DrawnShare(views[0]), 0.70);
  EXPECT_LT(DrawnShare(views[0]), 0.85);
  // The dense part, not the far points, is what the picture shows: its centre
  // has the ground's colour.
  EXPECT_EQ(views[0].at<cv::Vec3b>(100, 100)[2], 120);
}

// A sparse cloud is drawn with larger squares, closed into a surface; a dense
// one with single pixels: both cover the square, neither spills far past it.
TEST(CloudRenderTest, SplatsFollowTheDensity) {
  for (int n : {40, 600}) {
    const std::vector<cv::Mat> views = RenderCloudViews(Ground(n), 200);
    EXPECT_GT(DrawnShare(views[0]), 0.75) << n << " x " << n << " points";
    EXPECT_LT(DrawnShare(views[0]), 0.90) << n << " x " << n << " points";
  }
}

// From a camera at the origin looking along +z (f = 100, 200 x 100 pixels):
// a wall at z = 5 filling the right half of the view, and points behind the
// camera that would project onto the left half if their sign were ignored.
TEST(CloudRenderTest, TheViewFromACameraShowsWhatLiesInFrontOfIt) {
  CloudCamera camera;
  camera.K << 100, 0, 100, 0, 100, 50, 0, 0, 1;
  camera.width = 200;
  camera.height = 100;
  std::vector<colmap_io::PlyPoint> points;
  for (int i = 0; i <= 200; ++i) {
    for (int j = 0; j <= 200; ++j) {
      const double x = 5.0 * i / 200, y = -2.5 + 5.0 * j / 200;
      points.push_back(Point(x, y, 5, 120));    // cols 100..200 at full size
      points.push_back(Point(x, y, -5, 255));   // behind: cols 0..100 if z's sign were dropped
    }
  }
  const cv::Mat view = RenderCloudFromCamera(points, camera, 100);
  ASSERT_EQ(view.cols, 100);
  ASSERT_EQ(view.rows, 50);
  EXPECT_GT(DrawnShare(view(cv::Rect(52, 0, 48, 50))), 0.95);
  EXPECT_EQ(DrawnShare(view(cv::Rect(0, 0, 48, 50))), 0.0);
  EXPECT_EQ(view.at<cv::Vec3b>(25, 75)[2], 120);
}

TEST(CloudRenderTest, EmptyCloudsAndBadCameras) {
  for (const cv::Mat& view : RenderCloudViews({}, 50)) EXPECT_EQ(DrawnShare(view), 0.0);
  CloudCamera camera;
  EXPECT_THROW(RenderCloudFromCamera({}, camera, 100), std::invalid_argument);  // 0 x 0 pixels
  camera.width = camera.height = 10;
  EXPECT_THROW(RenderCloudFromCamera({}, camera, 0), std::invalid_argument);
  EXPECT_EQ(DrawnShare(RenderCloudFromCamera({}, camera, 10)), 0.0);
}

}  // namespace
}  // namespace dispmvs::eval
