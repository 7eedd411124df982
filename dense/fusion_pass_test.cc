// Fusion on exact maps (dense/test_workspace.h): the fused points lie on the
// example scene's surfaces, measured by ray casting the scene itself
// (examples/surface_distance.h), every point is seen by enough images, and
// stereo/fusion.cfg chooses the images. The claim of the geometric pass and
// fusion clears killed runs' temporaries, and only those, and only once held.

#include "dense/fusion_pass.h"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "colmap_io/stereo_config.h"
#include "dense/test_workspace.h"
#include "dense/view_claim.h"
#include "dense/workspace_maps.h"
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

TEST_F(FusionPassTest, TheClaimClearsWhatKilledRunsLeftAndOnlyThat) {
  const MapPaths geometric = PathsOf(workspace_, names_[2], kGeometricType);
  const MapPaths photometric = PathsOf(workspace_, names_[2], kPhotometricType);
  const fs::path report = root_ / "dispmvs_report.html";
  auto beside = [](const fs::path& path, const std::string& suffix) {
    return fs::path(path.string() + suffix);
  };
  // Temporaries a killed geometric pass, fusion or report writer leaves
  // (colmap_io/atomic_file.h's names; the cloud's bodies are NAME.points.tmp-PID).
  const std::vector<fs::path> leftovers = {
      beside(geometric.depth, ".tmp-999999-0"), beside(geometric.normal, ".tmp-999999-1"),
      beside(geometric.confidence, ".tmp-999999-2"), beside(ply_, ".points.tmp-999999"),
      beside(ply_, ".vis.points.tmp-999999"),    beside(ply_, ".tmp-999999-3"),
      beside(ply_, ".vis.tmp-999999-4"),         beside(report, ".tmp-999999-5")};
  // Not this claim's: a photometric map's temporary (its view's claim
  // governs it), PatchMatch's geometric map's, another cloud's body.
  const std::vector<fs::path> others = {
      beside(photometric.depth, ".tmp-999999-6"),
      workspace_.DepthMapsDir() / (names_[2] + ".geometric.bin.tmp-999999-7"),
      dir_.path() / "other.ply.points.tmp-999999"};
  for (const auto* paths : {&leftovers, &others}) {
    for (const fs::path& path : *paths) std::ofstream(path) << "killed writer";
  }

  {
    // Another process holds the claim: refused, and nothing is removed.
    const std::optional<ViewClaim> other = ViewClaim::TryClaim(FusionClaimPath(workspace_));
    ASSERT_TRUE(other.has_value());
    long holder = 0;
    EXPECT_FALSE(ClaimGeometricAndFusion(workspace_, plan_, ply_, {report}, log_, &holder));
    EXPECT_EQ(holder, static_cast<long>(::getpid()));
    for (const fs::path& path : leftovers) EXPECT_TRUE(fs::exists(path)) << path;
  }
  const std::optional<ViewClaim> claim =
      ClaimGeometricAndFusion(workspace_, plan_, ply_, {report}, log_);
  ASSERT_TRUE(claim.has_value());
  for (const fs::path& path : leftovers) EXPECT_FALSE(fs::exists(path)) << path;
  for (const fs::path& path : others) EXPECT_TRUE(fs::exists(path)) << path;
  EXPECT_NE(log_.str().find("fuse: removed 8 temporary file(s)"), std::string::npos) << log_.str();
  // Held now: a second run is refused while this one goes on.
  EXPECT_FALSE(ClaimGeometricAndFusion(workspace_, plan_, ply_, {report}, log_));
}

}  // namespace
}  // namespace dispmvs::dense
