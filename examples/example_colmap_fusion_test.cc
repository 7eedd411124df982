// Interop with the real COLMAP: the example's ground truth, exported as
// COLMAP "geometric" maps, is fused by `colmap stereo_fusion`, and the fused
// points are checked against the scene's exact surfaces. Fails when colmap is
// not installed: the project's install script provides it.

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/sparse_model.h"
#include "colmap_io/workspace.h"
#include "examples/example_workspace.h"
#include "examples/surface_distance.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::examples {
namespace {

namespace fs = std::filesystem;
using colmap_io::SparseModel;

constexpr uint64_t kSeed = 1;

// Fused points of a binary little-endian PLY as COLMAP's stereo_fusion writes
// it (x y z nx ny nz as float, red green blue as uchar); only the positions.
std::vector<Eigen::Vector3d> ReadColmapFusedPly(const fs::path& path) {
  const std::string bytes = testing::ReadFileBytes(path);
  const std::string end_marker = "end_header\n";
  const std::size_t header_end = bytes.find(end_marker);
  if (header_end == std::string::npos) {
    ADD_FAILURE() << path << ": no PLY header";
    return {};
  }
  const std::string header = bytes.substr(0, header_end);
  const std::string expected_properties =
      "property float x\nproperty float y\nproperty float z\n"
      "property float nx\nproperty float ny\nproperty float nz\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  EXPECT_NE(header.find("format binary_little_endian 1.0\n"), std::string::npos) << header;
  EXPECT_NE(header.find(expected_properties), std::string::npos) << header;
  const std::size_t count_at = header.find("element vertex ");
  if (count_at == std::string::npos) {
    ADD_FAILURE() << path << ": no vertex element";
    return {};
  }
  const std::size_t count = std::stoull(header.substr(count_at + 15));
  constexpr std::size_t kRecordSize = 6 * sizeof(float) + 3;
  const std::size_t payload = header_end + end_marker.size();
  if (bytes.size() - payload != count * kRecordSize) {
    ADD_FAILURE() << path << ": payload size does not match " << count << " vertices";
    return {};
  }
  std::vector<Eigen::Vector3d> points(count);
  for (std::size_t i = 0; i < count; ++i) {
    float xyz[3];
    std::memcpy(xyz, bytes.data() + payload + i * kRecordSize, sizeof(xyz));
    points[i] = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
  }
  return points;
}

// Fuses the ground truth with the real `colmap stereo_fusion` (exported as
// COLMAP "geometric" maps) and returns the sorted surface distances of the
// fused points; empty when colmap is not installed.
std::vector<double> FuseGroundTruthWithColmap(GroundTruthSampling sampling) {
  testing::TempDir dir;
  const fs::path root = dir.path() / "ws";
  ExampleWorkspaceOptions options;
  options.seed = kSeed;
  options.sampling = sampling;
  WriteExampleWorkspace(root, options);
  const colmap_io::Workspace workspace(root);
  const SparseModel model = workspace.ReadModel();
  for (const auto& [image_id, image] : model.images) {
    fs::copy_file(root / "ground_truth" / "depth_maps" / (image.name + ".bin"),
                  workspace.DepthMapPath(image.name, "geometric"));
    fs::copy_file(root / "ground_truth" / "normal_maps" / (image.name + ".bin"),
                  workspace.NormalMapPath(image.name, "geometric"));
  }
  const std::string command = "QT_QPA_PLATFORM=offscreen colmap stereo_fusion --workspace_path '" +
                              root.string() + "' --input_type geometric --output_path '" +
                              (root / "fused.ply").string() + "' > '" +
                              (root / "fusion.log").string() + "' 2>&1";
  const int status = std::system(command.c_str());
  EXPECT_EQ(status, 0) << testing::ReadFileBytes(root / "fusion.log");
  if (status != 0) return {};
  return SortedSurfaceDistances(ReadColmapFusedPly(root / "fused.ply"), model);
}

bool ColmapIsInstalled() { return std::system("command -v colmap > /dev/null 2>&1") == 0; }

// COLMAP's stereo_fusion back-projects depth-map pixel (col, row) through
// image position (col, row), not the pixel centre: ground truth sampled that
// way fuses onto the true surfaces up to float32 precision (coordinates of a
// few units: ulp ~5e-7; depths up to ~10: ~1e-6), while pixel-centre samples
// land half a pixel off (about 0.5 * depth / focal = 5e-3 to 2e-2 units along
// slanted surfaces). This pins down the convention maps exported for COLMAP
// must follow.
TEST(ExampleWorkspaceColmapTest, ColmapFusionOfGroundTruthUsesRawPixelIndices) {
  ASSERT_TRUE(ColmapIsInstalled())
      << "the colmap binary is not on PATH (install Debian's colmap package: .ci/install_deps.sh)";
  const auto exact = FuseGroundTruthWithColmap(GroundTruthSampling::kColmapDenseIndexing);
  ASSERT_GE(exact.size(), 10000u);
  EXPECT_LT(exact.back(), 1e-5) << "largest distance from the surfaces";

  const auto shifted = FuseGroundTruthWithColmap(GroundTruthSampling::kPixelCentres);
  ASSERT_GE(shifted.size(), 10000u);
  EXPECT_GT(shifted[shifted.size() / 2], 1e-3) << "median distance from the surfaces";
}

}  // namespace
}  // namespace dispmvs::examples
