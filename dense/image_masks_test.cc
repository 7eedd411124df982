// COLMAP's masks in the geometric pass and fusion, on exact maps
// (dense/test_workspace.h): black masks leave nothing, white masks change
// nothing (byte for byte), and half masks leave no point that any of its
// images sees through its masked half; the mask files' names and resampling
// follow COLMAP's fusion. The bounding box keeps every point inside it.

#include "dense/image_masks.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "dense/fusion_pass.h"
#include "dense/geometric_pass.h"
#include "dense/test_workspace.h"
#include "dense/workspace_maps.h"
#include "fusion/vis_file.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::dense {
namespace {

namespace fs = std::filesystem;

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(ImageMasksTest, ColmapsFileNamesResamplingAndRedChannel) {
  ::dispmvs::testing::TempDir dir;
  EXPECT_THROW(ImageMasks(dir.path() / "missing"), colmap_io::IoError);
  const ImageMasks masks(dir.path());
  EXPECT_FALSE(masks.PathOf("a.jpg"));
  EXPECT_TRUE(masks.Read("a.jpg", 4, 2).empty());  // no mask: used whole

  // NAME.png first; NAME itself only for a .png name without NAME.png.
  cv::Mat bgr(2, 4, CV_8UC3, cv::Scalar(0, 0, 255));  // red 255
  bgr.at<cv::Vec3b>(0, 1) = cv::Vec3b(255, 255, 0);   // red 0, others not: ignored
  ASSERT_TRUE(cv::imwrite((dir.path() / "a.jpg.png").string(), bgr));
  ASSERT_TRUE(cv::imwrite((dir.path() / "b.png").string(), bgr));
  EXPECT_EQ(*masks.PathOf("a.jpg"), dir.path() / "a.jpg.png");
  EXPECT_EQ(*masks.PathOf("b.png"), dir.path() / "b.png");
  EXPECT_FALSE(masks.PathOf("b.jpg"));
  const cv::Mat used = masks.Read("a.jpg", 4, 2);
  ASSERT_EQ(used.type(), CV_8U);
  EXPECT_EQ(cv::countNonZero(used == 0), 1);
  EXPECT_EQ(used.at<uint8_t>(0, 1), 0);

  // Resampled with a box filter: a 2x2 block stays ignored only if all of
  // it is 0. An 8x4 grey mask, black on its left half and one more pixel.
  cv::Mat grey(4, 8, CV_8U, cv::Scalar(200));
  grey(cv::Rect(0, 0, 4, 4)).setTo(0);
  grey.at<uint8_t>(0, 6) = 0;
  ASSERT_TRUE(cv::imwrite((dir.path() / "c.png.png").string(), grey));
  const cv::Mat half = masks.Read("c.png", 4, 2);
  EXPECT_EQ(cv::countNonZero(half(cv::Rect(0, 0, 2, 2))), 0);
  EXPECT_EQ(cv::countNonZero(half(cv::Rect(2, 0, 2, 2))), 4);

  fusion::DepthView view;
  view.depth = colmap_io::DenseArray(4, 2, 1, 5.0f);
  EXPECT_EQ(masks.Apply("c.png", &view), 4u);
  EXPECT_EQ(view.depth.data()[0], 0.0f);
  EXPECT_EQ(view.depth.data()[2], 5.0f);

  // A damaged mask is an error, not "use everything".
  std::ofstream(dir.path() / "d.png.png", std::ios::binary) << "\x89PNG\r\n\x1a\n broken";
  EXPECT_THROW(masks.Read("d.png", 4, 2), colmap_io::IoError);
  EXPECT_EQ(masks.CountWithMask({"a.jpg", "b.png", "b.jpg", "c.png", "d.png"}), 4u);
}

class MaskedPassesTest : public testing::ExactMapsTest {
 protected:
  fs::path masks_ = dir_.path() / "masks";

  // One mask per image at the maps' size: value 255, and 0 left of `black_until`.
  void WriteMasks(int black_until) {
    fs::create_directories(masks_);
    for (const std::string& name : names_) {
      const colmap_io::DenseArray depth = testing::GroundTruthDepth(root_, name);
      cv::Mat mask(depth.height(), depth.width(), CV_8U, cv::Scalar(255));
      mask(cv::Rect(0, 0, std::min(black_until, depth.width()), depth.height())).setTo(0);
      ASSERT_TRUE(cv::imwrite((masks_ / (name + ".png")).string(), mask));
    }
  }

  FusionSummary Fuse(const fs::path& ply, const ImageMasks& masks,
                     const fusion::FusionOptions& options = {}) {
    RunGeometricPass(workspace_, plan_, options.consistency, log_, masks);
    return RunFusion(workspace_, plan_, options, ply, log_, kDefaultFusionCacheBytes, masks);
  }
};

TEST_F(MaskedPassesTest, BlackMasksLeaveNothingWhiteMasksChangeNothing) {
  const fs::path plain = dir_.path() / "plain.ply";
  const FusionSummary unmasked = Fuse(plain, ImageMasks());
  ASSERT_GT(unmasked.num_points, 100000u);
  const std::string geometric = ReadBytes(PathsOf(workspace_, names_[0], kGeometricType).depth);

  WriteMasks(0);  // white
  const fs::path white = dir_.path() / "white.ply";
  const FusionSummary all_used = Fuse(white, ImageMasks(masks_));
  EXPECT_EQ(all_used.masked_pixels, 0u);
  EXPECT_EQ(ReadBytes(white), ReadBytes(plain));
  EXPECT_EQ(ReadBytes(white.string() + ".vis"), ReadBytes(plain.string() + ".vis"));
  EXPECT_EQ(ReadBytes(PathsOf(workspace_, names_[0], kGeometricType).depth), geometric);

  WriteMasks(1 << 20);  // black
  const fs::path black = dir_.path() / "black.ply";
  const FusionSummary none_used = Fuse(black, ImageMasks(masks_));
  EXPECT_EQ(none_used.num_points, 0u);
  EXPECT_EQ(none_used.masked_pixels, none_used.pixels);
  EXPECT_GT(none_used.pixels, 0u);
  for (const std::string& name : names_) {
    EXPECT_EQ(ValidFraction(colmap_io::ReadDenseArray(PathsOf(workspace_, name, kGeometricType).depth)), 0.0)
        << name;
  }
}

TEST_F(MaskedPassesTest, NoPointIsSeenThroughAMaskedHalf) {
  const fs::path plain = dir_.path() / "plain.ply";
  const std::size_t unmasked = Fuse(plain, ImageMasks()).num_points;
  const int width = testing::GroundTruthDepth(root_, names_[0]).width();
  WriteMasks(width / 2);
  const fs::path ply = dir_.path() / "half.ply";
  const FusionSummary summary = Fuse(ply, ImageMasks(masks_));
  // Half the pixels of every image ignored; points remain, fewer than half.
  EXPECT_EQ(summary.masked_pixels * 2, summary.pixels);
  ASSERT_GT(summary.num_points, unmasked / 10);
  EXPECT_LT(summary.num_points, unmasked / 2 + unmasked / 10);

  // The geometric maps keep nothing in the masked half.
  for (const std::string& name : names_) {
    const colmap_io::DenseArray depth =
        colmap_io::ReadDenseArray(PathsOf(workspace_, name, kGeometricType).depth);
    for (int row = 0; row < depth.height(); ++row) {
      for (int col = 0; col < width / 2; ++col) {
        ASSERT_EQ(depth.data()[static_cast<std::size_t>(row) * depth.width() + col], 0.0f) << name;
      }
    }
  }
  // Every image a point lists saw it through its unmasked half: the point
  // projects there (its pixels agree within --max_reproj_error, 1 px, and
  // the point is their mean: half a pixel more of slack).
  const std::vector<colmap_io::PlyPoint> points = colmap_io::ReadPlyPoints(ply);
  const auto visibility = fusion::ReadVisibilityFile(fs::path(ply.string() + ".vis"));
  ASSERT_EQ(points.size(), visibility.size());
  const std::vector<colmap_io::image_t> order = plan_.model.DenseImageOrder();
  std::vector<fusion::DepthView> views;
  for (colmap_io::image_t image_id : order) {
    views.push_back(LoadDepthView(workspace_, plan_, image_id, kPhotometricType));
  }
  double leftmost = 1e9;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d x(points[i].xyz[0], points[i].xyz[1], points[i].xyz[2]);
    for (uint32_t index : visibility[i]) {
      const fusion::DepthView& view = views.at(index);
      const Eigen::Vector3d p = view.K * (view.R * x + view.t);
      leftmost = std::min(leftmost, p.x() / p.z());
    }
  }
  EXPECT_GE(leftmost, width / 2 - 1.5);
}

TEST_F(MaskedPassesTest, BoundingBoxKeepsEveryPointInside) {
  const fs::path plain = dir_.path() / "plain.ply";
  const std::vector<colmap_io::PlyPoint> all = [&] {
    Fuse(plain, ImageMasks());
    return colmap_io::ReadPlyPoints(plain);
  }();
  // A box over the cloud's whole extent but the far half of x and the top
  // tenth of y.
  Eigen::Vector3d low(1e9, 1e9, 1e9), high(-1e9, -1e9, -1e9);
  for (const auto& point : all) {
    const Eigen::Vector3d x(point.xyz[0], point.xyz[1], point.xyz[2]);
    low = low.cwiseMin(x);
    high = high.cwiseMax(x);
  }
  fusion::FusionOptions options;
  const Eigen::Vector3d size = high - low;
  options.bounding_box = fusion::BoundingBox{low, high - Eigen::Vector3d(0.5 * size.x(), 0.1 * size.y(), 0)};
  std::size_t inside_before = 0;
  for (const auto& point : all) {
    inside_before += options.bounding_box->Contains(
        Eigen::Vector3d(point.xyz[0], point.xyz[1], point.xyz[2]));
  }
  const fs::path ply = dir_.path() / "boxed.ply";
  Fuse(ply, ImageMasks(), options);
  const std::vector<colmap_io::PlyPoint> boxed = colmap_io::ReadPlyPoints(ply);
  ASSERT_GT(inside_before, all.size() / 5);
  ASSERT_LT(inside_before, all.size() * 4 / 5);
  for (const auto& point : boxed) {
    // The mean of points inside a box is inside it (float rounding aside).
    const Eigen::Vector3d x(point.xyz[0], point.xyz[1], point.xyz[2]);
    const Eigen::Vector3d nearest_inside =
        x.cwiseMax(options.bounding_box->min).cwiseMin(options.bounding_box->max);
    ASSERT_LE((x - nearest_inside).norm(), 1e-5);
  }
  // Pixels near the faces may fuse differently, the bulk is the same.
  EXPECT_NEAR(static_cast<double>(boxed.size()), static_cast<double>(inside_before), 0.05 * inside_before);
}

}  // namespace
}  // namespace dispmvs::dense
