// Checks the example workspace: complete and readable with colmap_io, and its
// ground truth consistent with its sparse model. The sparse points are
// sampled directly on the scene's surfaces while the depth maps come from
// casting a ray per pixel, so agreement between the two checks the ray
// caster (and the pixel convention) independently.
//
// Under ctest the workspace is the one `dispmvs_make_example` wrote into the
// build directory (environment DISPMVS_EXAMPLE_WORKSPACE, set by the fixture
// in CMakeLists.txt); run by hand, the test generates its own.

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "colmap_io/dense_array.h"
#include "colmap_io/image_io.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/view_selection.h"
#include "colmap_io/workspace.h"
#include "examples/example_workspace.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::examples {
namespace {

namespace fs = std::filesystem;
using colmap_io::DenseArray;
using colmap_io::SparseModel;

constexpr uint64_t kSeed = 1;  // the seed the ctest fixture uses too

class ExampleWorkspaceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (const char* path = std::getenv("DISPMVS_EXAMPLE_WORKSPACE")) {
      root_ = new fs::path(path);
    } else {
      temp_dir_ = new testing::TempDir();
      root_ = new fs::path(temp_dir_->path() / "example");
      ExampleWorkspaceOptions options;
      options.seed = kSeed;
      WriteExampleWorkspace(*root_, options);
    }
  }
  static void TearDownTestSuite() {
    delete root_;
    delete temp_dir_;  // removes a generated workspace
    root_ = nullptr;
    temp_dir_ = nullptr;
  }

  static fs::path DepthPath(const std::string& name) {
    return *root_ / "ground_truth" / "depth_maps" / (name + ".bin");
  }
  static fs::path NormalPath(const std::string& name) {
    return *root_ / "ground_truth" / "normal_maps" / (name + ".bin");
  }

  // Where ground-truth pixel (col, row) was sampled, as an offset to both
  // indices, according to ground_truth/README.txt.
  static double SampleOffset() {
    const std::string readme = testing::ReadFileBytes(*root_ / "ground_truth" / "README.txt");
    if (readme.find("Sampling: pixel-centres.") != std::string::npos) return 0.5;
    if (readme.find("Sampling: colmap-dense.") != std::string::npos) return 0.0;
    ADD_FAILURE() << "ground_truth/README.txt names no sampling";
    return 0.5;
  }

  static fs::path* root_;
  static testing::TempDir* temp_dir_;
};

fs::path* ExampleWorkspaceTest::root_ = nullptr;
testing::TempDir* ExampleWorkspaceTest::temp_dir_ = nullptr;

// Camera-frame coordinates of a world point, computed from the stored
// quaternion directly.
Eigen::Vector3d ToCamera(const colmap_io::Image& image, const Eigen::Vector3d& xyz) {
  const Eigen::Quaterniond q(image.qvec(0), image.qvec(1), image.qvec(2), image.qvec(3));
  return q.normalized().toRotationMatrix() * xyz + image.tvec;
}

TEST_F(ExampleWorkspaceTest, IsACompleteReadableWorkspace) {
  const colmap_io::Workspace workspace(*root_);
  const SparseModel model = workspace.ReadModel();
  ASSERT_EQ(model.cameras.size(), 1u);
  const colmap_io::Camera& camera = model.cameras.begin()->second;
  EXPECT_EQ(camera.model_id, 1);  // PINHOLE
  EXPECT_EQ(camera.width, 320u);
  EXPECT_EQ(camera.height, 240u);
  ASSERT_EQ(model.images.size(), 7u);
  EXPECT_GE(model.points3D.size(), 500u);

  const auto entries = colmap_io::ReadPatchMatchConfig(workspace.PatchMatchConfigPath());
  const auto fusion_names = colmap_io::ReadFusionConfig(workspace.FusionConfigPath());
  ASSERT_EQ(entries.size(), model.images.size());
  EXPECT_EQ(fusion_names.size(), model.images.size());
  std::set<std::string> names;
  for (const auto& [image_id, image] : model.images) names.insert(image.name);
  for (const auto& entry : entries) {
    EXPECT_EQ(names.count(entry.reference), 1u) << entry.reference;
    EXPECT_EQ(entry.sources, colmap_io::SourceSpec::Auto(4));
  }
  for (const auto& name : fusion_names) EXPECT_EQ(names.count(name), 1u) << name;

  for (const auto& [image_id, image] : model.images) {
    const auto loaded = colmap_io::ReadImageForCamera(workspace.ImagePath(image.name),
                                                      model.cameras.at(image.camera_id), -1);
    EXPECT_EQ(loaded.image.cols, 320);
    const DenseArray depth = colmap_io::ReadDenseArray(DepthPath(image.name));
    const DenseArray normals = colmap_io::ReadDenseArray(NormalPath(image.name));
    EXPECT_EQ(depth.width(), 320);
    EXPECT_EQ(depth.height(), 240);
    EXPECT_EQ(depth.channels(), 1);
    EXPECT_EQ(normals.channels(), 3);
    // Every image sees enough of the scene for view selection to fill
    // "__auto__, 4".
    EXPECT_EQ(colmap_io::SelectSourceViews(model, image_id, 4).size(), 4u) << image.name;
  }
  for (const char* folder : {"depth_maps", "normal_maps", "consistency_graphs"}) {
    EXPECT_TRUE(fs::is_directory(workspace.StereoDir() / folder)) << folder;
  }
}

// Every observation of every sparse point: the stored 2-D position is the
// point's projection, and the ground-truth inverse depth interpolated
// bilinearly from the four pixel centres around it equals the point's
// inverse depth. Across a planar face inverse depth is affine in (u, v), so
// the interpolation is exact up to float32 storage (the generator only keeps
// observations whose four neighbours lie on the point's face).
TEST_F(ExampleWorkspaceTest, SparsePointsLieOnTheGroundTruthDepth) {
  const colmap_io::Workspace workspace(*root_);
  const SparseModel model = workspace.ReadModel();
  const double offset = SampleOffset();
  std::size_t num_checked = 0;
  double worst_relative_error = 0.0;
  for (const auto& [image_id, image] : model.images) {
    const auto& params = model.cameras.at(image.camera_id).params;
    const double fx = params[0], fy = params[1], cx = params[2], cy = params[3];
    const DenseArray depth = colmap_io::ReadDenseArray(DepthPath(image.name));
    const DenseArray normals = colmap_io::ReadDenseArray(NormalPath(image.name));
    std::size_t image_observations = 0;
    for (const auto& point2D : image.points2D) {
      if (!point2D.HasPoint3D()) continue;
      ++image_observations;
      const Eigen::Vector3d p = ToCamera(image, model.points3D.at(point2D.point3D_id).xyz);
      ASSERT_GT(p.z(), 0.0);
      const Eigen::Vector2d uv(fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy);
      ASSERT_LT((uv - point2D.xy).norm(), 1e-9) << image.name;

      // Ground-truth pixel (col, row) was sampled at (col, row) + offset.
      const double gx = uv.x() - offset;
      const double gy = uv.y() - offset;
      const int col = static_cast<int>(std::floor(gx));
      const int row = static_cast<int>(std::floor(gy));
      const double ax = gx - col;
      const double ay = gy - row;
      double inverse_depth = 0.0;
      for (int dy = 0; dy <= 1; ++dy) {
        for (int dx = 0; dx <= 1; ++dx) {
          const double d = depth.at(row + dy, col + dx);
          ASSERT_GT(d, 0.0) << image.name << " pixel " << col + dx << "," << row + dy;
          inverse_depth += (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay) / d;
        }
      }
      const double relative_error = std::abs(inverse_depth * p.z() - 1.0);
      worst_relative_error = std::max(worst_relative_error, relative_error);
      ASSERT_LT(relative_error, 1e-6) << image.name << " at " << uv.transpose();

      // The ground-truth normal at the nearest pixel is a unit vector facing
      // the camera, and the neighbours' back-projected points lie on the plane
      // it defines through the sparse point.
      Eigen::Vector3d n;
      for (int c = 0; c < 3; ++c) n[c] = normals.at(row, col, c);
      ASSERT_NEAR(n.norm(), 1.0, 1e-6);
      ASSERT_LT(n.dot(p), 0.0);
      for (int dy = 0; dy <= 1; ++dy) {
        for (int dx = 0; dx <= 1; ++dx) {
          const double d = depth.at(row + dy, col + dx);
          const Eigen::Vector3d q(d * (col + dx + offset - cx) / fx,
                                  d * (row + dy + offset - cy) / fy, d);
          ASSERT_LT(std::abs(n.dot(q - p)), 1e-5 * p.z());
        }
      }
      ++num_checked;
    }
    EXPECT_GE(image_observations, 100u) << image.name;
  }
  EXPECT_GE(num_checked, 1000u);
  RecordProperty("worst_relative_inverse_depth_error", std::to_string(worst_relative_error));
}

TEST_F(ExampleWorkspaceTest, GroundTruthCoversTheImages) {
  const colmap_io::Workspace workspace(*root_);
  const SparseModel model = workspace.ReadModel();
  for (const auto& [image_id, image] : model.images) {
    const DenseArray depth = colmap_io::ReadDenseArray(DepthPath(image.name));
    std::size_t valid = 0;
    for (const float d : depth.values()) {
      ASSERT_TRUE(std::isfinite(d));
      ASSERT_GE(d, 0.0f);
      if (d > 0.0f) ++valid;
    }
    // The cameras look down at an unbounded ground plane: every ray hits.
    EXPECT_EQ(valid, depth.size()) << image.name;
  }
}

// The program's output (or the suite's own generation) is reproduced bit for
// bit by another run with the same seed; another seed changes the texture and
// the sparse sample but not the geometry.
TEST_F(ExampleWorkspaceTest, IsDeterministicInTheSeed) {
  testing::TempDir dir;
  const fs::path same = dir.path() / "same";
  const fs::path other = dir.path() / "other";
  ExampleWorkspaceOptions options;
  options.seed = kSeed;
  WriteExampleWorkspace(same, options);
  options.seed = kSeed + 1;
  WriteExampleWorkspace(other, options);
  std::size_t num_files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(same)) {
    if (!entry.is_regular_file()) continue;
    const fs::path relative = fs::relative(entry.path(), same);
    EXPECT_EQ(testing::ReadFileBytes(entry.path()), testing::ReadFileBytes(*root_ / relative))
        << relative;
    ++num_files;
  }
  EXPECT_EQ(num_files, 3u + 7u + 14u + 1u + 2u);  // sparse, images, maps, README, cfgs
  const auto read = [](const fs::path& root, const char* relative) {
    return testing::ReadFileBytes(root / relative);
  };
  EXPECT_NE(read(same, "images/view_00.png"), read(other, "images/view_00.png"));
  EXPECT_NE(read(same, "sparse/points3D.bin"), read(other, "sparse/points3D.bin"));
  EXPECT_EQ(read(same, "sparse/cameras.bin"), read(other, "sparse/cameras.bin"));
  EXPECT_EQ(read(same, "ground_truth/depth_maps/view_03.png.bin"),
            read(other, "ground_truth/depth_maps/view_03.png.bin"));
}

}  // namespace
}  // namespace dispmvs::examples
