// Fusion on exact maps (dense/test_workspace.h): the fused points lie on the
// example scene's surfaces, measured by ray casting the scene itself
// (examples/surface_distance.h), every point is seen by enough images, and
// stereo/fusion.cfg chooses the images.

#include "dense/fusion_pass.h"

#include <algorithm>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "colmap_io/stereo_config.h"
#include "dense/test_workspace.h"
#include "examples/surface_distance.h"
#include "fusion/vis_file.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::dense {
namespace {

namespace fs = std::filesystem;

class FusionPassTest : public testing::ExactMapsTest {
 protected:
  fs::path ply_ = dir_.path() / "fused.ply";
};

TEST_F(FusionPassTest, ExactMapsFuseOntoTheSurfaces) {
  const fusion::GeometricFilterOptions options;
  const FusionSummary summary = RunFusion(workspace_, plan_, options, ply_, log_);
  EXPECT_EQ(summary.num_images, 7) << log_.str();
  ASSERT_GT(summary.num_points, 100000u);  // 185,955 measured

  const std::vector<colmap_io::PlyPoint> points = colmap_io::ReadPlyPoints(ply_);
  ASSERT_EQ(points.size(), summary.num_points);
  std::vector<Eigen::Vector3d> xyz;
  for (const auto& point : points) xyz.emplace_back(point.xyz[0], point.xyz[1], point.xyz[2]);
  const std::vector<double> distances = examples::SortedSurfaceDistances(xyz, plan_.model);
  // Scene depths are 3 to 10. Averaging exact points of one plane stays on
  // it, to float precision (measured: median 4e-8, p99 2.5e-7); only points
  // merged across an edge may be off (max 0.011).
  EXPECT_LT(distances[distances.size() / 2], 1e-6);
  EXPECT_LT(distances[distances.size() * 99 / 100], 1e-5);

  // Each point is seen by its reference and at least min_consistent_views
  // agreeing sources, all of them images of the workspace.
  const auto visibility = fusion::ReadVisibilityFile(fs::path(ply_.string() + ".vis"));
  ASSERT_EQ(visibility.size(), points.size());
  for (const auto& images : visibility) {
    ASSERT_GE(images.size(), static_cast<std::size_t>(options.min_consistent_views + 1));
    for (uint32_t index : images) ASSERT_LT(index, 7u);
  }
}

TEST_F(FusionPassTest, FusionConfigChoosesTheImages) {
  colmap_io::WriteFusionConfig({names_[1], names_[2], names_[3]}, workspace_.FusionConfigPath());
  const FusionSummary summary = RunFusion(workspace_, plan_, {}, ply_, log_);
  EXPECT_EQ(summary.num_images, 3) << log_.str();
  EXPECT_GT(summary.num_points, 0u);
  const auto visibility = fusion::ReadVisibilityFile(fs::path(ply_.string() + ".vis"));
  std::vector<uint32_t> seen;
  for (const auto& images : visibility) seen.insert(seen.end(), images.begin(), images.end());
  std::sort(seen.begin(), seen.end());
  seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
  EXPECT_LE(seen.size(), 3u);

  colmap_io::WriteFusionConfig({names_[1], "not_there.png"}, workspace_.FusionConfigPath());
  EXPECT_THROW(RunFusion(workspace_, plan_, {}, ply_, log_), colmap_io::IoError);
}

}  // namespace
}  // namespace dispmvs::dense
