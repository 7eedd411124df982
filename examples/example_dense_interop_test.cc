// Interop of dispmvs_colmap's outputs with the real COLMAP (Debian's 3.8):
//   * `--mode export` + `colmap stereo_fusion --input_type geometric` fuses
//     our maps onto the example's surfaces;
//   * `colmap poisson_mesher` and `colmap delaunay_mesher` accept our
//     fused.ply (+ .vis) and produce meshes;
//   * the same mask and bounding-box options, in COLMAP's spelling, leave
//     out the same regions in `colmap stereo_fusion` and in ours.
// These test the file formats and conventions, not the network: the
// photometric maps are the example's exact ground truth written under our
// names (depth, normals from depth as the photometric pass computes them,
// confidence 1), and `dispmvs_colmap --mode fuse` runs our geometric filter
// and fusion on them. So an exact pipeline must put the points on the
// surfaces to within float rounding, whatever the shipped weights are worth
// (example_dense_test.cc scores the network end to end). Fails when colmap is
// not installed: the project's install script provides it.

#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "colmap_io/workspace.h"
#include "examples/example_workspace.h"
#include "examples/surface_distance.h"
#include "fusion/depth_normals.h"
#include "fusion/vis_file.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::examples {
namespace {

namespace fs = std::filesystem;

constexpr const char* kType = "dispmvs.photometric";

// The example with its ground truth written as our photometric maps.
void WriteGroundTruthAsOurMaps(const fs::path& root) {
  const colmap_io::Workspace workspace(root);
  workspace.CreateStereoFolders();
  const colmap_io::SparseModel model = workspace.ReadModel();
  for (const auto& [image_id, image] : model.images) {
    const colmap_io::DenseArray depth =
        colmap_io::ReadDenseArray(root / "ground_truth" / "depth_maps" / (image.name + ".bin"));
    const Eigen::Matrix3d K = model.cameras.at(image.camera_id).CalibrationMatrix();
    colmap_io::WriteDenseArray(fusion::NormalMapFromDepth(depth, K),
                               workspace.NormalMapPath(image.name, kType));
    colmap_io::WriteDenseArray(colmap_io::DenseArray(depth.width(), depth.height(), 1, 1.0f),
                               workspace.ConfidenceMapPath(image.name, kType));
    colmap_io::WriteDenseArray(depth, workspace.DepthMapPath(image.name, kType));
  }
}

// Runs a shell command, output to `log`; returns the exit status.
int RunShell(const std::string& command, const fs::path& log) {
  const std::string full =
      "QT_QPA_PLATFORM=offscreen " + command + " > '" + log.string() + "' 2>&1";
  const int status = std::system(full.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

class ExampleDenseInteropTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_EQ(std::system("command -v colmap > /dev/null 2>&1"), 0)
        << "the colmap binary is not on PATH (install Debian's colmap package: "
           ".ci/install_deps.sh)";
    root_ = dir_.path() / "ws";
    ExampleWorkspaceOptions options;
    options.seed = 1;
    options.sampling = GroundTruthSampling::kColmapDenseIndexing;  // our maps' indexing
    WriteExampleWorkspace(root_, options);
    WriteGroundTruthAsOurMaps(root_);
    ASSERT_EQ(RunShell(std::string("'") + DISPMVS_COLMAP_PROGRAM + "' --mode fuse --workspace_path '" +
                           root_.string() + "'",
                       dir_.path() / "fuse.log"),
              0)
        << testing::ReadFileBytes(dir_.path() / "fuse.log");
    ASSERT_TRUE(fs::exists(root_ / "fused.ply"));
  }
  fs::path root_;
  testing::TempDir dir_;
};

TEST_F(ExampleDenseInteropTest, ColmapStereoFusionFusesOurExportedMaps) {
  const fs::path exported = dir_.path() / "colmap_ws";
  ASSERT_EQ(RunShell(std::string("'") + DISPMVS_COLMAP_PROGRAM + "' --mode export --workspace_path '" +
                    root_.string() + "' --export_path '" + exported.string() + "'",
                dir_.path() / "export.log"),
            0)
      << testing::ReadFileBytes(dir_.path() / "export.log");
  const fs::path fused = exported / "fused.ply";
  ASSERT_EQ(RunShell("colmap stereo_fusion --workspace_path '" + exported.string() +
                    "' --input_type geometric --output_path '" + fused.string() + "'",
                dir_.path() / "fusion.log"),
            0)
      << testing::ReadFileBytes(dir_.path() / "fusion.log");
  const auto points = colmap_io::ReadPlyPoints(fused);
  ASSERT_GT(points.size(), 1000u) << testing::ReadFileBytes(dir_.path() / "fusion.log");
  std::vector<Eigen::Vector3d> positions;
  for (const auto& p : points) positions.emplace_back(p.xyz[0], p.xyz[1], p.xyz[2]);
  const auto distances =
      SortedSurfaceDistances(positions, colmap_io::Workspace(root_).ReadModel());
  const double median = distances[distances.size() / 2];
  std::cout << "colmap stereo_fusion of our maps: " << points.size()
            << " points, surface distance median " << median << '\n';
  // Exact maps: COLMAP's fusion averages exact points (its own filtering
  // and the 1-pixel reprojection tolerance only choose which). Scene depths
  // are 3 to 10.
  EXPECT_LT(median, 1e-4);
}

// Our own fusion of exact maps: every point on a surface, every point seen by
// the reference and at least --min_num_consistent (2) sources.
TEST_F(ExampleDenseInteropTest, OurFusionOfExactMapsLiesOnTheSurfaces) {
  const auto points = colmap_io::ReadPlyPoints(root_ / "fused.ply");
  const auto visibility = fusion::ReadVisibilityFile(root_ / "fused.ply.vis");
  ASSERT_EQ(points.size(), visibility.size());
  ASSERT_GT(points.size(), 10000u);
  std::vector<Eigen::Vector3d> positions;
  for (std::size_t i = 0; i < points.size(); ++i) {
    positions.emplace_back(points[i].xyz[0], points[i].xyz[1], points[i].xyz[2]);
    ASSERT_GE(visibility[i].size(), 3u);
  }
  const auto distances = SortedSurfaceDistances(positions, colmap_io::Workspace(root_).ReadModel());
  std::cout << "our fusion of exact maps: " << points.size() << " points, surface distance median "
            << distances[distances.size() / 2] << ", max " << distances.back() << '\n';
  EXPECT_LT(distances[distances.size() / 2], 1e-4);
  EXPECT_LT(distances[distances.size() * 99 / 100], 1e-3);
}

TEST_F(ExampleDenseInteropTest, ColmapPoissonMesherAcceptsOurFusedCloud) {
  const fs::path mesh = dir_.path() / "poisson.ply";
  ASSERT_EQ(RunShell("colmap poisson_mesher --input_path '" + (root_ / "fused.ply").string() +
                    "' --output_path '" + mesh.string() + "'",
                dir_.path() / "poisson.log"),
            0)
      << testing::ReadFileBytes(dir_.path() / "poisson.log");
  const std::string bytes = testing::ReadFileBytes(mesh);
  EXPECT_NE(bytes.find("element face"), std::string::npos);
}

// The Delaunay mesher reads fused.ply.vis and looks up each listed image
// index in the workspace's model: a wrong index or a malformed file fails it.
// Debian 12's colmap is built without CGAL and refuses to run it: then the
// test is skipped, saying so (fusion/vis_file_test.cc checks the format
// byte for byte against COLMAP's writer layout instead).
TEST_F(ExampleDenseInteropTest, ColmapDelaunayMesherAcceptsOurFusedCloudAndVisibility) {
  const fs::path mesh = dir_.path() / "delaunay.ply";
  const fs::path log = dir_.path() / "delaunay.log";
  const int status = RunShell("colmap delaunay_mesher --input_type dense --input_path '" +
                                  root_.string() + "' --output_path '" + mesh.string() + "'",
                              log);
  const std::string text = testing::ReadFileBytes(log);
  if (status != 0 && text.find("requires CGAL") != std::string::npos) {
    GTEST_SKIP() << "this colmap has no Delaunay mesher (built without CGAL): " << text;
  }
  ASSERT_EQ(status, 0) << text;
  const std::string bytes = testing::ReadFileBytes(mesh);
  EXPECT_NE(bytes.find("element face"), std::string::npos);
}

// Where a cloud's points lie, for the mask and box comparison.
struct CloudRegions {
  std::size_t points = 0;
  std::size_t outside_box = 0;        // farther than float rounding from the box
  std::size_t seen_through_mask = 0;  // an image of the point's .vis sees it left of the cut
  double leftmost = 1e9;              // smallest column of a point in an image that lists it
};

CloudRegions Regions(const fs::path& ply, const colmap_io::SparseModel& model,
                     const Eigen::Vector3d& box_min, const Eigen::Vector3d& box_max,
                     double masked_until_col) {
  const auto points = colmap_io::ReadPlyPoints(ply);
  const auto visibility = fusion::ReadVisibilityFile(fs::path(ply.string() + ".vis"));
  EXPECT_EQ(points.size(), visibility.size());
  const std::vector<colmap_io::image_t> order = model.DenseImageOrder();
  CloudRegions regions;
  regions.points = points.size();
  for (std::size_t i = 0; i < points.size() && i < visibility.size(); ++i) {
    const Eigen::Vector3d x(points[i].xyz[0], points[i].xyz[1], points[i].xyz[2]);
    const Eigen::Vector3d inside = x.cwiseMax(box_min).cwiseMin(box_max);
    regions.outside_box += (x - inside).norm() > 1e-4 * (1 + x.norm()) ? 1 : 0;
    bool through_mask = false;
    for (uint32_t index : visibility[i]) {
      const colmap_io::Image& image = model.images.at(order.at(index));
      const Eigen::Matrix3d K = model.cameras.at(image.camera_id).CalibrationMatrix();
      const Eigen::Vector3d p = K * (image.RotationMatrix() * x + image.tvec);
      const double col = p.x() / p.z();
      regions.leftmost = std::min(regions.leftmost, col);
      through_mask = through_mask || col < masked_until_col;
    }
    regions.seen_through_mask += through_mask ? 1 : 0;
  }
  return regions;
}

// The same maps (our geometric maps, exported under COLMAP's names), the
// same masks (the left half of every image black), the same box (the lower
// half of the cloud's x extent) and the same 1 px reprojection tolerance
// (COLMAP's default is 2), given to both programs in COLMAP's spelling:
// neither keeps a point outside the box, nor one that an image of its
// visibility list sees through its masked half (beyond the tolerance and the
// averaging: 2 px), and both keep a similar share of their own unmasked
// clouds.
TEST_F(ExampleDenseInteropTest, MaskAndBoundingBoxLeaveOutTheSameRegionsAsColmap) {
  const fs::path exported = dir_.path() / "colmap_ws";
  ASSERT_EQ(RunShell(std::string("'") + DISPMVS_COLMAP_PROGRAM + "' --mode export --workspace_path '" +
                         root_.string() + "' --export_path '" + exported.string() + "'",
                     dir_.path() / "export.log"),
            0)
      << testing::ReadFileBytes(dir_.path() / "export.log");
  const colmap_io::SparseModel model = colmap_io::Workspace(root_).ReadModel();
  const fs::path masks = dir_.path() / "masks";
  fs::create_directories(masks);
  int width = 0;
  for (const auto& [image_id, image] : model.images) {
    const colmap_io::Camera& camera = model.cameras.at(image.camera_id);
    width = static_cast<int>(camera.width);
    cv::Mat mask(static_cast<int>(camera.height), width, CV_8U, cv::Scalar(255));
    mask(cv::Rect(0, 0, width / 2, mask.rows)).setTo(0);
    ASSERT_TRUE(cv::imwrite((masks / (image.name + ".png")).string(), mask));
  }
  Eigen::Vector3d low = Eigen::Vector3d::Constant(1e9), high = -low;
  for (const auto& point : colmap_io::ReadPlyPoints(root_ / "fused.ply")) {
    const Eigen::Vector3d x(point.xyz[0], point.xyz[1], point.xyz[2]);
    low = low.cwiseMin(x);
    high = high.cwiseMax(x);
  }
  const Eigen::Vector3d box_min = low - Eigen::Vector3d::Constant(1);
  const Eigen::Vector3d box_max(low.x() + 0.5 * (high.x() - low.x()), high.y() + 1, high.z() + 1);
  const fs::path bbox = dir_.path() / "bbox.txt";
  {
    std::ofstream out(bbox);
    out.precision(17);
    out << box_min.x() << ' ' << box_min.y() << ' ' << box_min.z() << '\n'
        << box_max.x() << ' ' << box_max.y() << ' ' << box_max.z() << '\n';
  }
  const std::string options = " --StereoFusion.max_reproj_error 1 --StereoFusion.mask_path '" +
                              masks.string() + "' --bbox_path '" + bbox.string() + "'";
  const fs::path colmap_plain = exported / "plain.ply", colmap_masked = exported / "masked.ply";
  for (const auto& [ply, extra] : {std::pair{colmap_plain, std::string(" --StereoFusion.max_reproj_error 1")},
                                   std::pair{colmap_masked, options}}) {
    ASSERT_EQ(RunShell("colmap stereo_fusion --workspace_path '" + exported.string() +
                           "' --input_type geometric --output_path '" + ply.string() + "'" + extra,
                       dir_.path() / "colmap.log"),
              0)
        << testing::ReadFileBytes(dir_.path() / "colmap.log");
  }
  const fs::path ours_masked = root_ / "masked.ply";
  ASSERT_EQ(RunShell(std::string("'") + DISPMVS_COLMAP_PROGRAM + "' --mode fuse --no_report --workspace_path '" +
                         root_.string() + "' --output_path '" + ours_masked.string() + "'" + options,
                     dir_.path() / "ours.log"),
            0)
      << testing::ReadFileBytes(dir_.path() / "ours.log");

  const double cut = width / 2 - 2.0;
  const CloudRegions colmap_all = Regions(colmap_plain, model, box_min, box_max, cut);
  const CloudRegions colmap_kept = Regions(colmap_masked, model, box_min, box_max, cut);
  const CloudRegions ours_all = Regions(root_ / "fused.ply", model, box_min, box_max, cut);
  const CloudRegions ours_kept = Regions(ours_masked, model, box_min, box_max, cut);
  auto line = [](const char* what, const CloudRegions& r) {
    std::cout << what << ": " << r.points << " points, " << r.outside_box << " outside the box, "
              << r.seen_through_mask << " seen through a masked half (leftmost column " << r.leftmost
              << ")\n";
  };
  line("colmap stereo_fusion, no mask or box", colmap_all);
  line("colmap stereo_fusion, mask and box", colmap_kept);
  line("dispmvs_colmap --mode fuse, no mask or box", ours_all);
  line("dispmvs_colmap --mode fuse, mask and box", ours_kept);
  // Without them, both clouds have points in every region left out below.
  ASSERT_GT(colmap_all.outside_box, colmap_all.points / 10);
  ASSERT_GT(colmap_all.seen_through_mask, colmap_all.points / 10);
  ASSERT_GT(ours_all.outside_box, ours_all.points / 10);
  ASSERT_GT(ours_all.seen_through_mask, ours_all.points / 10);
  // With them, neither has any there.
  ASSERT_GT(colmap_kept.points, 1000u);
  ASSERT_GT(ours_kept.points, 1000u);
  EXPECT_EQ(colmap_kept.outside_box, 0u);
  EXPECT_EQ(colmap_kept.seen_through_mask, 0u);
  EXPECT_EQ(ours_kept.outside_box, 0u);
  EXPECT_EQ(ours_kept.seen_through_mask, 0u);
  // And they keep about the same share of what they fuse without them.
  const double colmap_share = static_cast<double>(colmap_kept.points) / colmap_all.points;
  const double ours_share = static_cast<double>(ours_kept.points) / ours_all.points;
  std::cout << "share kept: colmap " << colmap_share << ", ours " << ours_share << '\n';
  EXPECT_NEAR(colmap_share, ours_share, 0.03);  // measured 0.115 and 0.128
}

// Through the command line: all-white masks change nothing (the same bytes),
// all-black masks fuse nothing and say why.
TEST_F(ExampleDenseInteropTest, WhiteMasksChangeNothingBlackMasksFuseNothingWithAWarning) {
  const colmap_io::SparseModel model = colmap_io::Workspace(root_).ReadModel();
  for (const int value : {255, 0}) {
    const fs::path masks = dir_.path() / ("masks" + std::to_string(value));
    fs::create_directories(masks);
    for (const auto& [image_id, image] : model.images) {
      const colmap_io::Camera& camera = model.cameras.at(image.camera_id);
      const cv::Mat mask(static_cast<int>(camera.height), static_cast<int>(camera.width), CV_8U,
                         cv::Scalar(value));
      ASSERT_TRUE(cv::imwrite((masks / (image.name + ".png")).string(), mask));
    }
    const fs::path ply = dir_.path() / ("masked" + std::to_string(value) + ".ply");
    const fs::path log = dir_.path() / ("masked" + std::to_string(value) + ".log");
    ASSERT_EQ(RunShell(std::string("'") + DISPMVS_COLMAP_PROGRAM + "' --mode fuse --no_report --workspace_path '" +
                           root_.string() + "' --output_path '" + ply.string() + "' --mask_path '" +
                           masks.string() + "'",
                       log),
              0)
        << testing::ReadFileBytes(log);
    const std::string text = testing::ReadFileBytes(log);
    EXPECT_NE(text.find("masks: 7 of 7 image(s) have a mask in"), std::string::npos) << text;
    if (value == 255) {
      EXPECT_EQ(testing::ReadFileBytes(ply), testing::ReadFileBytes(root_ / "fused.ply"));
      EXPECT_EQ(testing::ReadFileBytes(ply.string() + ".vis"),
                testing::ReadFileBytes(root_ / "fused.ply.vis"));
    } else {
      EXPECT_TRUE(colmap_io::ReadPlyPoints(ply).empty());
      EXPECT_NE(text.find(" has 0 points: the masks in " + masks.string() +
                          " (--mask_path) ignore every pixel of the 7 image(s) with depth maps"),
                std::string::npos)
          << text;
    }
  }
}

// A COLMAP command line's options carry over: in COLMAP's spelling they give
// the same cloud, byte for byte, as in ours, and not the default cloud.
TEST_F(ExampleDenseInteropTest, ColmapSpellingsMeanTheSameAsOurs) {
  const std::vector<std::pair<std::string, std::string>> runs = {
      {"colmap", " --StereoFusion.min_num_pixels 3 --StereoFusion.max_depth_error 0.005"
                 " --StereoFusion.max_reproj_error 0.75 --StereoFusion.max_num_pixels 3"
                 " --StereoFusion.check_num_images 3 --StereoFusion.max_normal_error 30"
                 " --StereoFusion.max_traversal_depth 2 --workspace_format COLMAP"},
      {"ours", " --min_num_consistent 2 --max_depth_error 0.005 --max_reproj_error 0.75"
               " --max_num_pixels 3 --check_num_images 3 --max_normal_error 30"
               " --max_traversal_depth 2"}};
  for (const auto& [name, options] : runs) {
    const fs::path log = dir_.path() / (name + ".log");
    ASSERT_EQ(RunShell(std::string("'") + DISPMVS_COLMAP_PROGRAM + "' --mode fuse --no_report --workspace_path '" +
                           root_.string() + "' --output_path '" + (dir_.path() / (name + ".ply")).string() +
                           "'" + options,
                       log),
              0)
        << testing::ReadFileBytes(log);
  }
  const std::string colmap = testing::ReadFileBytes(dir_.path() / "colmap.ply");
  EXPECT_EQ(colmap, testing::ReadFileBytes(dir_.path() / "ours.ply"));
  EXPECT_EQ(testing::ReadFileBytes(dir_.path() / "colmap.ply.vis"),
            testing::ReadFileBytes(dir_.path() / "ours.ply.vis"));
  EXPECT_NE(colmap, testing::ReadFileBytes(root_ / "fused.ply"));
}

}  // namespace
}  // namespace dispmvs::examples
