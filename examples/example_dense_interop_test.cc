// Interop of dispmvs_colmap's outputs with the real COLMAP (Debian's 3.8):
//   * `--mode export` + `colmap stereo_fusion --input_type geometric` fuses
//     our maps onto the example's surfaces;
//   * `colmap poisson_mesher` and `colmap delaunay_mesher` accept our
//     fused.ply (+ .vis) and produce meshes.
// Uses the run of the example_dense fixture (see CMakeLists.txt). Fails when
// colmap is not installed: the project's install script provides it.

#include <sys/wait.h>

#include <cstdlib>
#include <iostream>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/ply.h"
#include "colmap_io/workspace.h"
#include "examples/surface_distance.h"
#include "fusion/vis_file.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::examples {
namespace {

namespace fs = std::filesystem;

fs::path PreparedExample() {
  const char* prepared = std::getenv("DISPMVS_DENSE_EXAMPLE");
  return prepared == nullptr ? fs::path() : fs::path(prepared);
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
    root_ = PreparedExample();
    ASSERT_FALSE(root_.empty()) << "run through ctest (needs the example_dense fixture)";
    ASSERT_TRUE(fs::exists(root_ / "fused.ply")) << "the fixture run failed";
    ASSERT_EQ(std::system("command -v colmap > /dev/null 2>&1"), 0)
        << "the colmap binary is not on PATH (install Debian's colmap package: "
           ".ci/install_deps.sh)";
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
  // Same bound as our own fusion's (example_dense_test.cc).
  EXPECT_LT(median, DISPMVS_E2E_MAX_FUSED_MEDIAN_DISTANCE);
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
TEST_F(ExampleDenseInteropTest, ColmapDelaunayMesherAcceptsOurFusedCloudAndVisibility) {
  const fs::path mesh = dir_.path() / "delaunay.ply";
  ASSERT_EQ(RunShell("colmap delaunay_mesher --input_type dense --input_path '" + root_.string() +
                    "' --output_path '" + mesh.string() + "'",
                dir_.path() / "delaunay.log"),
            0)
      << testing::ReadFileBytes(dir_.path() / "delaunay.log");
  const std::string bytes = testing::ReadFileBytes(mesh);
  EXPECT_NE(bytes.find("element face"), std::string::npos);
}

}  // namespace
}  // namespace dispmvs::examples
