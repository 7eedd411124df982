// The real `colmap` binary accepts a written scene's sparse model, and fuses
// its ground truth onto the true surfaces. Fails (not skips) when colmap is
// not installed, hence the ctest label "interop".

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

#include "colmap_io/ply.h"
#include "colmap_io/sparse_model_io.h"
#include "colmap_io/workspace.h"
#include "synth/raycast.h"
#include "synth/workspace_writer.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::synth {
namespace {

TEST(SynthWorkspaceColmapTest, ModelAnalyzerAcceptsTheSparseModel) {
  ASSERT_EQ(std::system("command -v colmap > /dev/null 2>&1"), 0)
      << "the colmap binary is not on PATH (install Debian's colmap package)";
  SynthWorkspaceOptions options;
  options.config.width = 96;
  options.config.height = 64;
  options.config.num_views = 3;
  testing::TempDir dir;
  WriteSynthWorkspace(dir.path() / "ws", options, 11);
  const colmap_io::SparseModel model = colmap_io::ReadSparseModel(dir.path() / "ws" / "sparse");

  const auto log = dir.path() / "analyzer.log";
  const std::string command = "QT_QPA_PLATFORM=offscreen colmap model_analyzer --path '" +
                              (dir.path() / "ws" / "sparse").string() + "' > '" + log.string() + "' 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << testing::ReadFileBytes(log);
  const std::string output = testing::ReadFileBytes(log);
  EXPECT_NE(output.find("Cameras: 3"), std::string::npos) << output;
  EXPECT_NE(output.find("Images: 3"), std::string::npos) << output;
  EXPECT_NE(output.find("Points: " + std::to_string(model.points3D.size())), std::string::npos) << output;
}

// Ground truth exported as COLMAP "geometric" maps and fused by the real
// stereo_fusion must land on the scene's surfaces: each fused point's depth
// equals, to float32 precision plus the small chord error of averaging
// neighbouring samples of curved surfaces, the depth a fresh ray through its
// projection hits in the view that sees it best. Were the maps sampled half a
// pixel off (at pixel centres), slanted surfaces would be off by about
// 0.5 / focal (~6e-3 here, focal ~ 80 px) relative, far above the bound.
TEST(SynthWorkspaceColmapTest, StereoFusionOfGroundTruthLandsOnTheSurfaces) {
  ASSERT_EQ(std::system("command -v colmap > /dev/null 2>&1"), 0)
      << "the colmap binary is not on PATH (install Debian's colmap package)";
  SynthWorkspaceOptions options;
  options.config.width = 96;
  options.config.height = 64;
  options.config.num_views = 4;
  constexpr uint64_t kSeed = 13;
  testing::TempDir dir;
  const auto root = dir.path() / "ws";
  WriteSynthWorkspace(root, options, kSeed);
  const colmap_io::Workspace workspace(root);
  const colmap_io::SparseModel model = workspace.ReadModel();
  for (const auto& [image_id, image] : model.images) {
    std::filesystem::copy_file(root / "ground_truth" / "depth_maps" / (image.name + ".bin"),
                               workspace.DepthMapPath(image.name, "geometric"));
    std::filesystem::copy_file(root / "ground_truth" / "normal_maps" / (image.name + ".bin"),
                               workspace.NormalMapPath(image.name, "geometric"));
  }
  // Four views give at most four pixels per point: lower COLMAP's default of 5.
  const std::string command = "QT_QPA_PLATFORM=offscreen colmap stereo_fusion --workspace_path '" +
                              root.string() + "' --input_type geometric --StereoFusion.min_num_pixels 2 " +
                              "--output_path '" + (root / "fused.ply").string() + "' > '" +
                              (root / "fusion.log").string() + "' 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << testing::ReadFileBytes(root / "fusion.log");
  const std::vector<colmap_io::PlyPoint> fused = colmap_io::ReadPlyPoints(root / "fused.ply");
  ASSERT_GE(fused.size(), 1000u);

  const SynthScene scene = DrawScene(options.config, kSeed);
  RaycastOptions raycast;
  raycast.dtype = torch::kDouble;
  // Per point, the smallest error over the views it projects into (one
  // batched cast per view).
  std::vector<double> errors(fused.size(), std::numeric_limits<double>::infinity());
  for (const auto& [image_id, image] : model.images) {
    const Eigen::Matrix3d K = model.cameras.at(image.camera_id).CalibrationMatrix();
    std::vector<size_t> index;
    std::vector<double> depth, xy;
    for (size_t i = 0; i < fused.size(); ++i) {
      const Eigen::Vector3d xyz(fused[i].xyz[0], fused[i].xyz[1], fused[i].xyz[2]);
      const Eigen::Vector3d p = image.RotationMatrix() * xyz + image.tvec;
      if (!(p.z() > 0)) continue;
      const Eigen::Vector3d uvw = K * p;
      const double u = uvw.x() / uvw.z(), v = uvw.y() / uvw.z();
      if (!(u >= 0 && u <= 96 && v >= 0 && v <= 64)) continue;
      index.push_back(i);
      depth.push_back(p.z());
      xy.push_back(u - 0.5);  // COLMAP position -> pixel index
      xy.push_back(v - 0.5);
    }
    if (index.empty()) continue;
    const torch::Tensor pixels =
        torch::tensor(xy, torch::kDouble).view({static_cast<int64_t>(index.size()), 2});
    const torch::Tensor hits =
        CastPixels(scene.scene, scene.cameras[image_id - 1], pixels, raycast).depth.contiguous();
    const auto hit = hits.accessor<double, 1>();
    for (size_t k = 0; k < index.size(); ++k) {
      const double error = std::abs(hit[static_cast<int64_t>(k)] * scene.scale - depth[k]) / depth[k];
      errors[index[k]] = std::min(errors[index[k]], error);
    }
  }
  std::sort(errors.begin(), errors.end());
  std::cout << "fused " << fused.size() << " points; relative depth error median "
            << errors[errors.size() / 2] << ", p90 " << errors[errors.size() * 9 / 10] << "\n";
  EXPECT_LT(errors[errors.size() / 2], 1e-5) << "median relative depth error";
  EXPECT_LT(errors[errors.size() * 9 / 10], 1e-4) << "90th percentile";
}

}  // namespace
}  // namespace dispmvs::synth
