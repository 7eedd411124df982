// The workspace of a rectified pair, read back through colmap_io and checked
// against geometry computed here from the disparity field's formula.

#include "bench/stereo_pair_workspace.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/camera_models.h"
#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/workspace.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::bench {
namespace {

namespace fs = std::filesystem;
using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::TempDir;

constexpr int kWidth = 12, kHeight = 8;
constexpr double kInf = std::numeric_limits<double>::infinity();

StereoPairCalibration Calibration() {
  StereoPairCalibration c;
  c.focal = 20;
  c.cx = 6.3;
  c.cy = 4.1;
  c.doffs = 2.5;
  c.baseline = 0.7;
  return c;
}

// The disparity field in left pixel-centre indices (x = col, y = row): a
// slanted plane, and a nearer block (+3 px) at cols >= 8, rows >= 4.
bool InBlock(double x, double y) { return x >= 8 && y >= 4; }
double PlaneDisparity(double x, double y) { return 1.5 + 0.1 * x - 0.05 * y; }
double FieldDisparity(int col, int row) {
  return PlaneDisparity(col, row) + (InBlock(col, row) ? 3.0 : 0.0);
}

// Unknown disparities: inf, NaN, and one with d + doffs <= 0.
const std::set<std::pair<int, int>>& UnknownPixels() {  // (row, col)
  static const std::set<std::pair<int, int>> unknown = {{3, 2}, {1, 5}, {6, 1}};
  return unknown;
}

NpyMatrix Disparity() {
  NpyMatrix m;
  m.rows = kHeight;
  m.cols = kWidth;
  m.descr = "<f4";
  for (int row = 0; row < kHeight; ++row) {
    for (int col = 0; col < kWidth; ++col) m.values.push_back(FieldDisparity(col, row));
  }
  m.values[3 * kWidth + 2] = kInf;
  m.values[1 * kWidth + 5] = std::nan("");
  m.values[6 * kWidth + 1] = -2.5;  // d + doffs = 0
  return m;
}

cv::Mat TestImage(int width, int height, int seed) {
  cv::Mat image(height, width, CV_8UC3);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      image.at<cv::Vec3b>(r, c) = cv::Vec3b(static_cast<uint8_t>((r * 37 + c * 11 + seed) % 256),
                                            static_cast<uint8_t>((r * 5 + c * 53) % 256),
                                            static_cast<uint8_t>((seed * 7 + c) % 256));
    }
  }
  return image;
}

class StereoPairWorkspaceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    options_.left_image = dir_.path() / "in" / "l.png";
    options_.right_image = dir_.path() / "in" / "r.png";
    fs::create_directories(dir_.path() / "in");
    ASSERT_TRUE(cv::imwrite(options_.left_image.string(), TestImage(kWidth, kHeight, 1)));
    ASSERT_TRUE(cv::imwrite(options_.right_image.string(), TestImage(kWidth, kHeight, 2)));
    options_.calibration = Calibration();
    options_.num_sparse_points = 1000000;  // every candidate
    ws_ = dir_.path() / "ws";
  }

  StereoPairWorkspaceSummary Write() {
    return WriteStereoPairWorkspace(ws_, Disparity(), dir_.path() / "d.npy", options_);
  }

  TempDir dir_;
  StereoPairWorkspaceOptions options_;
  fs::path ws_;
};

TEST_F(StereoPairWorkspaceTest, CamerasPosesAndFiles) {
  const StereoPairWorkspaceSummary summary = Write();
  EXPECT_EQ(summary.left_name, "left.png");
  EXPECT_EQ(summary.right_name, "right.png");
  EXPECT_EQ(summary.valid_disparities, kWidth * kHeight - 3);

  const colmap_io::Workspace workspace(ws_);
  const colmap_io::SparseModel model = workspace.ReadModel();
  ASSERT_EQ(model.cameras.size(), 2u);
  ASSERT_EQ(model.images.size(), 2u);
  const colmap_io::Image* left = model.FindImageByName("left.png");
  const colmap_io::Image* right = model.FindImageByName("right.png");
  ASSERT_NE(left, nullptr);
  ASSERT_NE(right, nullptr);
  const colmap_io::Camera& left_camera = model.cameras.at(left->camera_id);
  const colmap_io::Camera& right_camera = model.cameras.at(right->camera_id);
  EXPECT_EQ(left_camera.model_id, colmap_io::kPinholeModelId);
  EXPECT_EQ(right_camera.model_id, colmap_io::kPinholeModelId);
  EXPECT_EQ(left_camera.params, (std::vector<double>{20, 20, 6.3, 4.1}));
  EXPECT_EQ(right_camera.params, (std::vector<double>{20, 20, 6.3 + 2.5, 4.1}));
  EXPECT_EQ(left_camera.width, static_cast<uint64_t>(kWidth));
  EXPECT_EQ(right_camera.height, static_cast<uint64_t>(kHeight));
  EXPECT_TRUE(left->RotationMatrix().isIdentity(1e-15));
  EXPECT_TRUE(right->RotationMatrix().isIdentity(1e-15));
  EXPECT_TRUE(left->ProjectionCenter().isZero(1e-15));
  EXPECT_LT((right->ProjectionCenter() - Eigen::Vector3d(0.7, 0, 0)).norm(), 1e-15);
  EXPECT_LT((right->tvec - Eigen::Vector3d(-0.7, 0, 0)).norm(), 1e-15);  // t = -R C

  // Images byte for byte; each image has the other as its source.
  EXPECT_EQ(ReadFileBytes(ws_ / "images" / "left.png"), ReadFileBytes(options_.left_image));
  EXPECT_EQ(ReadFileBytes(ws_ / "images" / "right.png"), ReadFileBytes(options_.right_image));
  const std::vector<colmap_io::PatchMatchEntry> entries =
      colmap_io::ReadPatchMatchConfig(workspace.PatchMatchConfigPath());
  ASSERT_EQ(entries.size(), 2u);
  EXPECT_EQ(entries[0].reference, "left.png");
  EXPECT_EQ(entries[0].sources, colmap_io::SourceSpec::Explicit({"right.png"}));
  EXPECT_EQ(entries[1].reference, "right.png");
  EXPECT_EQ(entries[1].sources, colmap_io::SourceSpec::Explicit({"left.png"}));
  EXPECT_EQ(colmap_io::ReadFusionConfig(workspace.FusionConfigPath()),
            (std::vector<std::string>{"left.png", "right.png"}));
  EXPECT_TRUE(fs::is_directory(workspace.DepthMapsDir()));
  EXPECT_TRUE(fs::is_regular_file(ws_ / "ground_truth" / "README.txt"));
  for (const auto& entry : fs::recursive_directory_iterator(ws_)) {
    EXPECT_EQ(entry.path().string().find(".tmp-"), std::string::npos) << entry.path();
  }
}

TEST_F(StereoPairWorkspaceTest, GroundTruthDepthProjectsToTheMatchingRightPixel) {
  const StereoPairWorkspaceSummary summary = Write();
  const colmap_io::SparseModel model = colmap_io::Workspace(ws_).ReadModel();
  const colmap_io::Image& left = *model.FindImageByName("left.png");
  const colmap_io::Image& right = *model.FindImageByName("right.png");
  const Eigen::Matrix3d K_left = model.cameras.at(left.camera_id).CalibrationMatrix();
  const Eigen::Matrix3d K_right = model.cameras.at(right.camera_id).CalibrationMatrix();
  const colmap_io::DenseArray gt =
      colmap_io::ReadDenseArray(ws_ / "ground_truth" / "depth_maps" / "left.png.bin");
  ASSERT_EQ(gt.width(), kWidth);
  ASSERT_EQ(gt.height(), kHeight);

  int64_t expected_pixels = 0, expected_dropped = 0;
  for (int row = 0; row < kHeight; ++row) {
    for (int col = 0; col < kWidth; ++col) {
      // GT pixel (col, row) is image position (col, row): pixel-centre index
      // (col - 0.5, row - 0.5), between four disparity samples.
      bool known = row >= 1 && col >= 1;
      for (int r = row - 1; known && r <= row; ++r) {
        for (int c = col - 1; c <= col; ++c) known = known && UnknownPixels().count({r, c}) == 0;
      }
      const double x = col - 0.5, y = row - 0.5;
      // The block's edge runs between samples 7|8 and 3|4: a corner straddles
      // it when its four samples are not all on one side.
      const bool straddles = known && InBlock(col, row) != InBlock(col - 1, row - 1);
      const float depth = gt.at(row, col);
      if (!known || straddles) {
        EXPECT_EQ(depth, 0.0f) << col << "," << row;
        expected_dropped += straddles;
        continue;
      }
      ++expected_pixels;
      ASSERT_GT(depth, 0.0f) << col << "," << row;
      const double disparity = PlaneDisparity(x, y) + (InBlock(col, row) ? 3.0 : 0.0);
      // Back-project with the model's left camera and pose, project into the
      // right one: the Middlebury match x_right = x_left - d, same row.
      const Eigen::Vector3d camera_point = depth * (K_left.inverse() * Eigen::Vector3d(col, row, 1));
      const Eigen::Vector3d world =
          left.RotationMatrix().transpose() * (camera_point - left.tvec);
      const Eigen::Vector3d uvw = K_right * (right.RotationMatrix() * world + right.tvec);
      const double x_right = uvw.x() / uvw.z(), y_right = uvw.y() / uvw.z();
      EXPECT_NEAR(x_right, col - disparity, 1e-6 * kWidth) << col << "," << row;
      EXPECT_NEAR(y_right, row, 1e-6 * kHeight) << col << "," << row;
      // And the depth itself: z = B f / (d + doffs).
      EXPECT_NEAR(depth, 0.7 * 20 / (disparity + 2.5), 1e-6 * depth);
    }
  }
  EXPECT_EQ(summary.gt_pixels, expected_pixels);
  EXPECT_EQ(summary.gt_dropped_at_edges, expected_dropped);
  EXPECT_GT(expected_dropped, 0);
  EXPECT_GT(expected_pixels, kWidth * kHeight / 2);
}

TEST_F(StereoPairWorkspaceTest, SparsePointsAreVisibleTwoViewMatches) {
  const StereoPairWorkspaceSummary summary = Write();
  const colmap_io::SparseModel model = colmap_io::Workspace(ws_).ReadModel();
  const colmap_io::Image& left = *model.FindImageByName("left.png");
  const colmap_io::Image& right = *model.FindImageByName("right.png");
  const NpyMatrix disparity = Disparity();
  ASSERT_GT(model.points3D.size(), 20u);
  EXPECT_EQ(summary.num_points3D, static_cast<int64_t>(model.points3D.size()));
  EXPECT_EQ(summary.sparse_candidates, summary.num_points3D);  // all taken

  std::set<std::pair<int, int>> sources;  // (row, col) of each point's left pixel
  for (const auto& [id, point] : model.points3D) {
    ASSERT_EQ(point.track.size(), 2u);
    Eigen::Vector2d xy_left, xy_right;
    for (const colmap_io::TrackElement& element : point.track) {
      const Eigen::Vector2d xy = model.images.at(element.image_id).points2D[element.point2D_idx].xy;
      (element.image_id == left.image_id ? xy_left : xy_right) = xy;
    }
    // A left pixel centre (COLMAP: index + 0.5), its disparity, and the match.
    const int col = static_cast<int>(std::floor(xy_left.x()));
    const int row = static_cast<int>(std::floor(xy_left.y()));
    EXPECT_NEAR(xy_left.x(), col + 0.5, 1e-9);
    EXPECT_NEAR(xy_left.y(), row + 0.5, 1e-9);
    ASSERT_EQ(UnknownPixels().count({row, col}), 0u);
    const double d = FieldDisparity(col, row);
    EXPECT_NEAR(xy_left.x() - xy_right.x(), d, 1e-9);
    EXPECT_NEAR(xy_right.y(), xy_left.y(), 1e-9);
    EXPECT_NEAR(point.xyz.z(), 0.7 * 20 / (d + 2.5), 1e-12);
    EXPECT_GE(xy_right.x(), 0.0);
    EXPECT_LT(xy_right.x(), kWidth);
    // The right camera sees the point where the track says.
    const Eigen::Matrix3d K_right = model.cameras.at(right.camera_id).CalibrationMatrix();
    const Eigen::Vector3d uvw = K_right * (right.RotationMatrix() * point.xyz + right.tvec);
    EXPECT_NEAR(uvw.x() / uvw.z(), xy_right.x(), 1e-9);
    // Not occluded: no pixel of the row with a disparity over 1 px larger
    // lands on the same right pixel.
    for (int other = 0; other < kWidth; ++other) {
      const double d_other = disparity.at(row, other);
      if (!std::isfinite(d_other) || !(d_other - d > 1.0)) continue;
      EXPECT_NE(std::floor(other + 0.5 - d_other), std::floor(xy_right.x()))
          << "(" << col << ", " << row << ") hidden by column " << other;
    }
    sources.insert({row, col});
  }
  // Row 5: the plane's col lands at right x = 0.9 col - 0.75, the block's
  // (cols 8-11) at 0.9 col - 3.75, on right pixels 3-6: it hides the plane's
  // cols 5-7 (right pixels 3-5); col 4 (x 2.85) is seen, col 0 (x -0.75)
  // lands left of the right image.
  for (const int col : {0, 5, 6, 7}) EXPECT_EQ(sources.count({5, col}), 0u) << col;
  for (const int col : {1, 2, 3, 4, 8, 9, 10, 11}) EXPECT_EQ(sources.count({5, col}), 1u) << col;

  // Fewer points: evenly spaced, a subset of the candidates.
  options_.num_sparse_points = 7;
  ASSERT_NO_THROW(Write());
  const colmap_io::SparseModel fewer = colmap_io::Workspace(ws_).ReadModel();
  ASSERT_EQ(fewer.points3D.size(), 7u);
  for (const auto& [id, point] : fewer.points3D) {
    const Eigen::Vector2d xy = fewer.images.at(point.track[0].image_id).points2D[point.track[0].point2D_idx].xy;
    if (point.track[0].image_id != left.image_id) continue;
    EXPECT_EQ(sources.count({static_cast<int>(xy.y()), static_cast<int>(xy.x())}), 1u);
  }
}

TEST_F(StereoPairWorkspaceTest, RefusesBadInput) {
  const auto expect_io_error = [&](const NpyMatrix& disparity, const std::string& fragment) {
    try {
      WriteStereoPairWorkspace(ws_, disparity, dir_.path() / "d.npy", options_);
      ADD_FAILURE() << "no error, expected " << fragment;
    } catch (const colmap_io::IoError& error) {
      EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos) << error.what();
    }
  };
  NpyMatrix small = Disparity();
  small.cols = kWidth - 1;
  small.values.resize(static_cast<std::size_t>(small.rows * small.cols));
  expect_io_error(small, "d.npy: disparity map is 11x8 (cols x rows) but the left image is 12x8");
  NpyMatrix unknown = Disparity();
  for (double& d : unknown.values) d = kInf;
  expect_io_error(unknown, "no valid disparity");
  // Every pixel lands left of the right image: no sparse point.
  NpyMatrix far = Disparity();
  for (double& d : far.values) d = 40;
  expect_io_error(far, "no sparse point");
  EXPECT_FALSE(fs::exists(ws_));  // nothing written for bad input

  const fs::path wide = dir_.path() / "in" / "wide.png";
  ASSERT_TRUE(cv::imwrite(wide.string(), TestImage(kWidth + 1, kHeight, 3)));
  options_.right_image = wide;
  expect_io_error(Disparity(), "wide.png: right image is 13x8 but the left image is 12x8");
  options_.right_image = dir_.path() / "in" / "none.png";
  expect_io_error(Disparity(), "none.png");

  StereoPairWorkspaceOptions bad = options_;
  bad.calibration.focal = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = options_;
  bad.calibration.baseline = -1;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = options_;
  bad.calibration.cx = std::nan("");
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = options_;
  bad.num_sparse_points = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad = options_;
  bad.max_disparity_step = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::bench
