#include "synth/workspace_writer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include <Eigen/Core>

#include "colmap_io/dense_array.h"
#include "colmap_io/image_io.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model_io.h"
#include "colmap_io/stereo_config.h"
#include "synth/raycast.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::synth {
namespace {

namespace fs = std::filesystem;
using testing::ReadFileBytes;
using testing::TempDir;

constexpr uint64_t kSeed = 7;

SynthWorkspaceOptions SmallOptions() {
  SynthWorkspaceOptions options;
  options.config.width = 96;
  options.config.height = 64;
  options.config.num_views = 4;
  options.config.min_objects = 4;
  options.config.max_objects = 8;
  options.sparse_points_per_view = 150;
  return options;
}

// Bilinear interpolation of a depth map at COLMAP position (u, v), the
// samples sitting at integer positions; NaN where a sample is missing.
double InterpolateDepth(const colmap_io::DenseArray& depth, double u, double v) {
  const int c0 = std::min(static_cast<int>(std::floor(u)), depth.width() - 2);
  const int r0 = std::min(static_cast<int>(std::floor(v)), depth.height() - 2);
  if (c0 < 0 || r0 < 0) return std::nan("");
  const double a = u - c0, b = v - r0;
  const double d[4] = {depth.at(r0, c0), depth.at(r0, c0 + 1), depth.at(r0 + 1, c0), depth.at(r0 + 1, c0 + 1)};
  for (double x : d) {
    if (!(x > 0)) return std::nan("");
  }
  return (1 - b) * ((1 - a) * d[0] + a * d[1]) + b * ((1 - a) * d[2] + a * d[3]);
}

// One workspace shared by the read-back tests (writing it is the slow part).
class WrittenWorkspaceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = std::make_unique<TempDir>();
    summary_ = WriteSynthWorkspace(dir_->path() / "ws", SmallOptions(), kSeed);
  }
  static void TearDownTestSuite() { dir_.reset(); }
  static fs::path Root() { return dir_->path() / "ws"; }

  static std::unique_ptr<TempDir> dir_;
  static SynthWorkspaceSummary summary_;
};
std::unique_ptr<TempDir> WrittenWorkspaceTest::dir_;
SynthWorkspaceSummary WrittenWorkspaceTest::summary_;

TEST_F(WrittenWorkspaceTest, CamerasAndPosesAreTheGeneratorsInColmapConvention) {
  const SynthScene scene = DrawScene(SmallOptions().config, kSeed);
  const colmap_io::SparseModel model = colmap_io::ReadSparseModel(Root() / "sparse");
  ASSERT_EQ(model.images.size(), 4u);
  ASSERT_EQ(model.cameras.size(), 4u);
  EXPECT_EQ(summary_.rig, RigName(scene.rig));
  for (int i = 0; i < 4; ++i) {
    const PinholeCamera& expected = scene.cameras[static_cast<size_t>(i)];
    const colmap_io::Image& image = model.images.at(static_cast<colmap_io::image_t>(i + 1));
    const colmap_io::Camera& camera = model.cameras.at(image.camera_id);
    EXPECT_EQ(image.name, "view_0" + std::to_string(i) + ".png");
    EXPECT_EQ(camera.model_id, 1);  // PINHOLE
    EXPECT_EQ(camera.width, 96u);
    EXPECT_EQ(camera.height, 64u);
    ASSERT_EQ(camera.params.size(), 4u);
    EXPECT_DOUBLE_EQ(camera.params[0], expected.fx);
    EXPECT_DOUBLE_EQ(camera.params[1], expected.fy);
    EXPECT_DOUBLE_EQ(camera.params[2], expected.cx + 0.5);
    EXPECT_DOUBLE_EQ(camera.params[3], expected.cy + 0.5);
    const Eigen::Matrix3d R = image.RotationMatrix();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(R(r, c), expected.rotation(r, c), 1e-12);
      EXPECT_NEAR(image.tvec[r], scene.scale * expected.translation[r], 1e-12 * scene.scale);
    }
  }
}

TEST_F(WrittenWorkspaceTest, SparsePointsReprojectAndLieOnEveryTrackViewsGroundTruth) {
  const SynthScene scene = DrawScene(SmallOptions().config, kSeed);
  const colmap_io::SparseModel model = colmap_io::ReadSparseModel(Root() / "sparse");
  ASSERT_GE(model.points3D.size(), 50u) << "too few sparse points to test anything";
  size_t checked = 0;
  for (const auto& [id, point] : model.points3D) {
    ASSERT_GE(point.track.size(), 2u);
    for (const colmap_io::TrackElement& element : point.track) {
      const colmap_io::Image& image = model.images.at(element.image_id);
      const colmap_io::Camera& camera = model.cameras.at(image.camera_id);
      const Eigen::Vector3d p = image.RotationMatrix() * point.xyz + image.tvec;
      ASSERT_GT(p.z(), 0);
      const Eigen::Vector3d uvw = camera.CalibrationMatrix() * p;
      const Eigen::Vector2d uv(uvw.x() / uvw.z(), uvw.y() / uvw.z());
      EXPECT_LT((uv - image.points2D.at(element.point2D_idx).xy).norm(), 1e-3);

      // On the written ground truth, which samples COLMAP position (col, row).
      const colmap_io::DenseArray depth =
          colmap_io::ReadDenseArray(Root() / "ground_truth" / "depth_maps" / (image.name + ".bin"));
      const double interpolated = InterpolateDepth(depth, uv.x(), uv.y());
      EXPECT_NEAR(interpolated, p.z(), 1e-4 * p.z()) << "point " << id << " in " << image.name;

      // And on the scene itself: a fresh ray through the observation (pixel
      // index = COLMAP position - 0.5) hits at the point's depth.
      const torch::Tensor xy = torch::tensor({uv.x() - 0.5, uv.y() - 0.5}, torch::kDouble).view({1, 2});
      RaycastOptions raycast;
      raycast.dtype = torch::kDouble;
      const RayHits hit = CastPixels(scene.scene, scene.cameras[element.image_id - 1], xy, raycast);
      EXPECT_NEAR(hit.depth.item<double>() * scene.scale, p.z(), 1e-4 * p.z());
      ++checked;
    }
  }
  EXPECT_EQ(checked, summary_.num_observations);
}

TEST_F(WrittenWorkspaceTest, ImagesDecodeToTheGeneratedValues) {
  const SynthSample sample = GenerateSample(SmallOptions().config, kSeed, torch::kCPU);
  for (int i = 0; i < 4; ++i) {
    const cv::Mat rgb = colmap_io::ReadImageRgb(Root() / "images" / ("view_0" + std::to_string(i) + ".png"));
    ASSERT_EQ(rgb.rows, 64);
    ASSERT_EQ(rgb.cols, 96);
    const auto expected = sample.images[i].to(torch::kDouble).contiguous();
    const auto a = expected.accessor<double, 3>();
    double worst = 0;
    for (int row = 0; row < 64; ++row) {
      for (int col = 0; col < 96; ++col) {
        const cv::Vec3f& p = rgb.at<cv::Vec3f>(row, col);
        for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(p[c] - a[c][row][col]));
      }
    }
    EXPECT_LE(worst, 0.5 / 255 + 1e-6) << "view " << i;
  }
}

TEST_F(WrittenWorkspaceTest, GroundTruthCloudAndConfigs) {
  const auto cloud = colmap_io::ReadPlyPoints(Root() / "ground_truth" / "points.ply");
  // One point per positive depth sample on the stride-2 grid of every view.
  size_t expected = 0;
  for (int i = 0; i < 4; ++i) {
    const auto depth = colmap_io::ReadDenseArray(Root() / "ground_truth" / "depth_maps" /
                                                 ("view_0" + std::to_string(i) + ".png.bin"));
    for (int row = 0; row < 64; row += 2)
      for (int col = 0; col < 96; col += 2) expected += depth.at(row, col) > 0;
  }
  EXPECT_EQ(cloud.size(), expected);
  EXPECT_EQ(summary_.num_ground_truth_points, expected);
  for (const auto& point : cloud) {
    const double norm = std::hypot(point.normal[0], point.normal[1], point.normal[2]);
    ASSERT_NEAR(norm, 1.0, 1e-5);
  }
  const auto entries = colmap_io::ReadPatchMatchConfig(Root() / "stereo" / "patch-match.cfg");
  ASSERT_EQ(entries.size(), 4u);
  for (const auto& entry : entries) EXPECT_EQ(entry.sources, colmap_io::SourceSpec::Auto(3));
  EXPECT_EQ(colmap_io::ReadFusionConfig(Root() / "stereo" / "fusion.cfg").size(), 4u);
  EXPECT_TRUE(fs::is_directory(Root() / "stereo" / "depth_maps"));
  const std::string readme = ReadFileBytes(Root() / "ground_truth" / "README.txt");
  EXPECT_NE(readme.find("Sampling: colmap-dense"), std::string::npos);
}

// With the outdoor sky at infinity the written ground truth has no depth on
// the sky (where the finite sky's is hundreds of units away), the same depth
// elsewhere but where the finite depth is as far (the horizon), and no
// sparse point lies on the sky.
TEST(SynthDatasetTest, SkyAtInfinityHasNoGroundTruthAndNoSparsePoints) {
  TempDir tmp;
  SynthWorkspaceOptions finite = SmallOptions();
  finite.config = ConfigForRig("outdoor", finite.config);
  SynthWorkspaceOptions infinite = finite;
  infinite.config.background_at_infinity = true;
  WriteSynthWorkspace(tmp.path() / "finite", finite, kSeed);
  WriteSynthWorkspace(tmp.path() / "infinite", infinite, kSeed);
  const double scale = DrawScene(finite.config, kSeed).scale;
  int64_t sky = 0;
  for (int i = 0; i < 4; ++i) {
    const std::string name = "view_0" + std::to_string(i) + ".png.bin";
    const auto a = colmap_io::ReadDenseArray(tmp.path() / "finite" / "ground_truth" / "depth_maps" / name);
    const auto b = colmap_io::ReadDenseArray(tmp.path() / "infinite" / "ground_truth" / "depth_maps" / name);
    for (int row = 0; row < 64; ++row) {
      for (int col = 0; col < 96; ++col) {
        if (b.at(row, col) == 0) {
          ++sky;
          EXPECT_GT(a.at(row, col), 300 * scale);
        } else if (a.at(row, col) != b.at(row, col)) {
          EXPECT_GT(a.at(row, col), 300 * scale);
        }
      }
    }
  }
  EXPECT_GT(sky, 4 * 64 * 96 / 20);
  const colmap_io::SparseModel model = colmap_io::ReadSparseModel(tmp.path() / "infinite" / "sparse");
  ASSERT_GE(model.points3D.size(), 20u);
  for (const auto& [id, point] : model.points3D) {
    for (const colmap_io::TrackElement& element : point.track) {
      const colmap_io::Image& image = model.images.at(element.image_id);
      const colmap_io::Camera& camera = model.cameras.at(image.camera_id);
      const Eigen::Vector3d uvw = camera.CalibrationMatrix() * (image.RotationMatrix() * point.xyz + image.tvec);
      const auto depth = colmap_io::ReadDenseArray(tmp.path() / "infinite" / "ground_truth" / "depth_maps" /
                                                   (image.name + ".bin"));
      // Some ground-truth sample around the observation has a depth (all
      // four are 0 on the sky).
      const int c0 = std::clamp(static_cast<int>(std::floor(uvw.x() / uvw.z())), 0, 94);
      const int r0 = std::clamp(static_cast<int>(std::floor(uvw.y() / uvw.z())), 0, 62);
      const float nearest = std::max({depth.at(r0, c0), depth.at(r0, c0 + 1), depth.at(r0 + 1, c0), depth.at(r0 + 1, c0 + 1)});
      EXPECT_GT(nearest, 0) << "point " << id << " in " << image.name;
    }
  }
}

TEST(SynthDatasetTest, IsDeterministicAndSkipsCompleteScenesOnReRun) {
  SynthWorkspaceOptions options = SmallOptions();
  options.config.num_views = 2;
  TempDir dir;
  const SynthDatasetSummary first = WriteSynthDataset(dir.path(), 2, 3, options);
  EXPECT_EQ(first.written, 2);
  EXPECT_EQ(first.skipped, 0);
  const fs::path model_file = dir.path() / "scene_001" / "sparse" / "points3D.bin";
  const std::string first_bytes = ReadFileBytes(model_file);

  const SynthDatasetSummary again = WriteSynthDataset(dir.path(), 2, 3, options);
  EXPECT_EQ(again.written, 0);
  EXPECT_EQ(again.skipped, 2);

  // An interrupted run: scene_001 missing, a stale half-written folder left.
  fs::remove_all(dir.path() / "scene_001");
  testing::WriteFileBytes(dir.path() / "scene_001.tmp" / "junk", "x");
  const SynthDatasetSummary resumed = WriteSynthDataset(dir.path(), 3, 3, options);
  EXPECT_EQ(resumed.written, 2);  // scene_001 again, and the new scene_002
  EXPECT_EQ(resumed.skipped, 1);
  EXPECT_FALSE(fs::exists(dir.path() / "scene_001.tmp"));
  EXPECT_FALSE(fs::exists(dir.path() / "scene_001" / "junk"));
  EXPECT_EQ(ReadFileBytes(model_file), first_bytes);  // same seed, same bytes
  EXPECT_NE(ReadFileBytes(dir.path() / "scene_002" / "sparse" / "points3D.bin"), first_bytes);
}

TEST(SynthDatasetTest, BadOptionsGiveClearErrors) {
  auto message_of = [](const auto& call) -> std::string {
    try {
      call();
    } catch (const std::invalid_argument& error) {
      return error.what();
    }
    return "no exception";
  };
  EXPECT_NE(message_of([] { ConfigForRig("sideways", SynthConfig{}); }).find("unknown rig 'sideways'"),
            std::string::npos);
  EXPECT_EQ(ConfigForRig("outdoor", SynthConfig{}).p_table, 0);
  EXPECT_EQ(ConfigForRig("outdoor", SynthConfig{}).p_outdoor, 1);
  TempDir dir;
  EXPECT_NE(message_of([&] { WriteSynthDataset(dir.path(), 0, 1, SmallOptions()); }).find("num_scenes"),
            std::string::npos);
  SynthWorkspaceOptions options = SmallOptions();
  options.config.width = 4;
  EXPECT_NE(message_of([&] { WriteSynthDataset(dir.path(), 1, 1, options); }).find("height and width"),
            std::string::npos);
  options = SmallOptions();
  options.config.supersampling = 4;  // even: no centre ray
  EXPECT_NE(message_of([&] { WriteSynthDataset(dir.path(), 1, 1, options); }).find("supersampling must be odd"),
            std::string::npos);
  options = SmallOptions();
  options.ply_stride = 0;
  EXPECT_NE(message_of([&] { WriteSynthWorkspace(dir.path() / "ws", options, 1); }).find("ply_stride"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(dir.path() / "scene_000"));
  EXPECT_FALSE(fs::exists(dir.path() / "ws"));
}

TEST(SynthDatasetTest, SceneSeedsAndNames) {
  EXPECT_EQ(SceneFolderName(0), "scene_000");
  EXPECT_EQ(SceneFolderName(1234), "scene_1234");
  EXPECT_EQ(SceneSeed(5, 2), SceneSeed(5, 2));
  EXPECT_NE(SceneSeed(5, 2), SceneSeed(5, 3));
  EXPECT_NE(SceneSeed(5, 1), SceneSeed(6, 0));
}

}  // namespace
}  // namespace dispmvs::synth
