// dispmvs_make_large_workspace at 30 images, checked only through what any
// reader of the workspace sees (colmap_io, Eigen): the maps are the exact
// plane, the sparse observations are the exact projections of their points,
// and dispmvs_colmap fuses the maps onto the plane. The generator's own code
// is not used here, so a shared mistake cannot hide.

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/image_io.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/workspace.h"
#include "tests/support/run_program.h"
#include "tests/support/temp_dir.h"

namespace dispmvs {
namespace {

namespace fs = std::filesystem;
using colmap_io::DenseArray;

constexpr int kImages = 30;  // a full row of 20 and part of a second
constexpr int kWidth = 160;
constexpr int kHeight = 120;
constexpr int kPointsPerImage = 40;
// Maps hold float32: the exact depth rounded to float is off by at most half
// a unit in the last place, 2^-24 relative. Beyond that the geometry must be
// exact to 1e-9.
constexpr double kFloatRounding = 0x1.0p-24;
constexpr double kExact = 1e-9;

// One workspace for the whole suite (generating it is most of the time).
class LargeWorkspaceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    root_ = dir_->path() / "ws";
    const testing::ProgramRun run = testing::RunProgram(
        *dir_, DISPMVS_MAKE_LARGE_WORKSPACE_PROGRAM,
        "--output_path '" + root_.string() + "' --images " + std::to_string(kImages) +
            " --width " + std::to_string(kWidth) + " --height " + std::to_string(kHeight) +
            " --points_per_image " + std::to_string(kPointsPerImage) + " --seed 3");
    generated_ = run.status == 0;
    generator_output_ = run.out + run.err;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }

  void SetUp() override {
    ASSERT_TRUE(generated_) << generator_output_;
    workspace_ = std::make_unique<colmap_io::Workspace>(root_);
    model_ = workspace_->ReadModel();  // validates tracks against points2D both ways
  }

  static testing::TempDir* dir_;
  static fs::path root_;
  static bool generated_;
  static std::string generator_output_;
  std::unique_ptr<colmap_io::Workspace> workspace_;
  colmap_io::SparseModel model_;
};

testing::TempDir* LargeWorkspaceTest::dir_ = nullptr;
fs::path LargeWorkspaceTest::root_;
bool LargeWorkspaceTest::generated_ = false;
std::string LargeWorkspaceTest::generator_output_;

TEST_F(LargeWorkspaceTest, LayoutIsAsUndistorterWritesIt) {
  ASSERT_EQ(model_.cameras.size(), 1u);
  const colmap_io::Camera& camera = model_.cameras.begin()->second;
  EXPECT_EQ(camera.model_id, 1);  // PINHOLE
  EXPECT_EQ(camera.width, static_cast<uint64_t>(kWidth));
  EXPECT_EQ(camera.height, static_cast<uint64_t>(kHeight));
  ASSERT_EQ(model_.images.size(), static_cast<std::size_t>(kImages));
  for (const auto& [id, image] : model_.images) {
    EXPECT_TRUE(fs::is_regular_file(workspace_->ImagePath(image.name))) << image.name;
    EXPECT_TRUE(fs::is_regular_file(workspace_->DepthMapPath(image.name, "dispmvs.photometric")));
  }
  const cv::Mat first = colmap_io::ReadImageRgb(workspace_->ImagePath(model_.images.at(1).name));
  EXPECT_EQ(first.cols, kWidth);
  EXPECT_EQ(first.rows, kHeight);
  // `__auto__` for every image: nothing that would override it.
  EXPECT_FALSE(fs::exists(workspace_->PatchMatchConfigPath()));
  EXPECT_FALSE(fs::exists(workspace_->FusionConfigPath()));
}

// Depth pixel (col, row) back-projected along K^-1 (col, row, 1) lands on
// z = 0; normals are the plane's, facing the camera; confidence 1.
TEST_F(LargeWorkspaceTest, DepthMapsBackProjectOntoThePlane) {
  const Eigen::Matrix3d K_inverse = model_.cameras.begin()->second.CalibrationMatrix().inverse();
  int checked = 0;
  for (const colmap_io::image_t id : {1u, 2u, 15u, 21u, 30u}) {
    const colmap_io::Image& image = model_.images.at(id);
    const Eigen::Matrix3d R = image.RotationMatrix();
    const Eigen::Vector3d centre = image.ProjectionCenter();
    ASSERT_GT(centre.z(), 0.0);
    const DenseArray depth = colmap_io::ReadDenseArray(
        workspace_->DepthMapPath(image.name, "dispmvs.photometric"));
    const DenseArray normal = colmap_io::ReadDenseArray(
        workspace_->NormalMapPath(image.name, "dispmvs.photometric"));
    const DenseArray confidence = colmap_io::ReadDenseArray(
        workspace_->ConfidenceMapPath(image.name, "dispmvs.photometric"));
    ASSERT_EQ(depth.width(), kWidth);
    ASSERT_EQ(depth.height(), kHeight);
    ASSERT_EQ(normal.channels(), 3);
    const Eigen::Vector3d plane_normal = R * Eigen::Vector3d(0, 0, 1);  // world +z, camera frame
    for (int row = 0; row < kHeight; row += 17) {
      for (const int col : {0, 1, 37, kWidth / 2, kWidth - 1}) {
        const double d = depth.at(row, col);
        ASSERT_GT(d, 0.0);
        const Eigen::Vector3d camera_ray = K_inverse * Eigen::Vector3d(col, row, 1.0);
        const Eigen::Vector3d world_ray = R.transpose() * camera_ray;
        const Eigen::Vector3d x = centre + d * world_ray;
        // x.z = (d - d_exact) * world_ray.z: the relative depth error.
        EXPECT_LE(std::abs(x.z()) / (d * std::abs(world_ray.z())), kFloatRounding + kExact)
            << image.name << " (" << col << ", " << row << "): z = " << x.z();
        const Eigen::Vector3d n(normal.at(row, col, 0), normal.at(row, col, 1),
                                normal.at(row, col, 2));
        EXPECT_LE((n - plane_normal).norm(), 1e-7) << image.name;
        EXPECT_LT(n.dot(camera_ray), 0.0) << "normal must face the camera";
        EXPECT_EQ(confidence.at(row, col), 1.0f);
        ++checked;
      }
    }
    // The forward tilt: depth changes from the top rows to the bottom ones.
    EXPECT_GT(std::abs(depth.at(0, kWidth / 2) - depth.at(kHeight - 1, kWidth / 2)),
              0.1 * depth.at(0, kWidth / 2));
  }
  EXPECT_EQ(checked, 5 * 8 * 5);
}

Eigen::Vector2d Project(const colmap_io::Camera& camera, const colmap_io::Image& image,
                        const Eigen::Vector3d& xyz, double* camera_z) {
  const Eigen::Vector3d p = camera.CalibrationMatrix() * (image.RotationMatrix() * xyz + image.tvec);
  *camera_z = p.z();
  return p.hnormalized();
}

// Every observation is the exact projection of its point, points lie on the
// plane, and a point is observed by exactly the images whose frame holds it.
TEST_F(LargeWorkspaceTest, SparseObservationsAreExactAndComplete) {
  const colmap_io::Camera& camera = model_.cameras.begin()->second;
  ASSERT_GT(model_.points3D.size(), 50u);
  std::size_t observations = 0;
  for (const auto& [point_id, point] : model_.points3D) {
    EXPECT_EQ(point.xyz.z(), 0.0);
    EXPECT_GE(point.track.size(), 2u) << "SfM keeps only triangulated points";
    std::set<colmap_io::image_t> observers;
    for (const colmap_io::TrackElement& element : point.track) {
      const colmap_io::Image& image = model_.images.at(element.image_id);
      const colmap_io::Point2D& observed = image.points2D.at(element.point2D_idx);
      ASSERT_EQ(observed.point3D_id, point_id);
      double z = 0;
      const Eigen::Vector2d projected = Project(camera, image, point.xyz, &z);
      EXPECT_LE((projected - observed.xy).norm(), kExact)
          << image.name << " point " << point_id;
      observers.insert(element.image_id);
      ++observations;
    }
    for (const auto& [image_id, image] : model_.images) {
      double z = 0;
      const Eigen::Vector2d uv = Project(camera, image, point.xyz, &z);
      const bool in_frame =
          z > 0 && uv.x() >= 0 && uv.x() < kWidth && uv.y() >= 0 && uv.y() < kHeight;
      EXPECT_EQ(in_frame, observers.count(image_id) == 1)
          << "point " << point_id << " in " << image.name << " at " << uv.transpose();
    }
  }
  // About kPointsPerImage observations per image (fewer at the grid's edges).
  const double per_image = static_cast<double>(observations) / kImages;
  EXPECT_GT(per_image, 0.5 * kPointsPerImage);
  EXPECT_LT(per_image, 1.5 * kPointsPerImage);
}

// The texture is a function of the ground position: every view shows a
// sparse point in the point's colour (up to the texture's change within a
// pixel and 8-bit rounding).
TEST_F(LargeWorkspaceTest, ViewsAgreeInColour) {
  std::map<colmap_io::image_t, cv::Mat> images;
  double sum = 0;
  std::size_t count = 0;
  for (const auto& [point_id, point] : model_.points3D) {
    for (const colmap_io::TrackElement& element : point.track) {
      const colmap_io::Image& image = model_.images.at(element.image_id);
      cv::Mat& rgb = images[element.image_id];
      if (rgb.empty()) rgb = colmap_io::ReadImageRgb(workspace_->ImagePath(image.name));
      const Eigen::Vector2d xy = image.points2D.at(element.point2D_idx).xy;
      const cv::Vec3f c = rgb.at<cv::Vec3f>(static_cast<int>(xy.y()), static_cast<int>(xy.x()));
      for (int k = 0; k < 3; ++k) sum += std::abs(c[k] - point.rgb[k] / 255.0);
      count += 3;
    }
  }
  ASSERT_GT(count, 0u);
  EXPECT_LT(sum / count, 0.03);
}

// Neighbours on the grid see the ground from directions well over 1 degree
// apart (COLMAP's minimum triangulation angle for a source view).
TEST_F(LargeWorkspaceTest, NeighboursHaveAWideTriangulationAngle) {
  const auto angle_deg = [&](colmap_io::image_t a, colmap_io::image_t b) {
    const Eigen::Vector3d ca = model_.images.at(a).ProjectionCenter();
    const Eigen::Vector3d cb = model_.images.at(b).ProjectionCenter();
    const Eigen::Vector3d ground((ca.x() + cb.x()) / 2, (ca.y() + cb.y()) / 2, 0.0);
    const Eigen::Vector3d ra = ca - ground, rb = cb - ground;
    return std::atan2(ra.cross(rb).norm(), ra.dot(rb)) * 180.0 / 3.14159265358979323846;
  };
  EXPECT_GT(angle_deg(1, 2), 5.0);   // along a row
  EXPECT_GT(angle_deg(1, 21), 5.0);  // across rows
}

// `--mode fuse` on the exact maps: exit 0, and every fused point on z = 0.
TEST_F(LargeWorkspaceTest, FusionPutsEveryPointOnThePlane) {
  const testing::ProgramRun run = testing::RunProgram(
      *dir_, DISPMVS_COLMAP_PROGRAM, "--workspace_path '" + root_.string() + "' --mode fuse");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  EXPECT_NE(run.out.find("summary: geometric: " + std::to_string(kImages) + " done"),
            std::string::npos)
      << run.out;
  const std::vector<colmap_io::PlyPoint> points = colmap_io::ReadPlyPoints(root_ / "fused.ply");
  // Most of the 30 x 160 x 120 pixels agree with their sources; fusion merges
  // the pixels of one ground point seen in several views.
  ASSERT_GT(points.size(), 10000u) << run.out;
  double worst = 0;
  for (const colmap_io::PlyPoint& point : points) {
    worst = std::max(worst, std::abs(static_cast<double>(point.xyz[2])));
  }
  EXPECT_LE(worst, 1e-4);
}

}  // namespace
}  // namespace dispmvs
