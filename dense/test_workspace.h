#pragma once
// Test fixture of dense/: the embedded example workspace (examples/) with its
// exact ground-truth depth and normal maps copied in as photometric maps
// (NAME.dispmvs.photometric.bin, confidence 1), as if the network had been
// perfect. The geometric pass, fusion and export can then be checked against
// the scene's exact geometry, without running the network.

#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/dense_array.h"
#include "colmap_io/workspace.h"
#include "dense/plan.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::dense::testing {

// Writes the example (seed 1, ground truth on COLMAP's dense index grid, the
// grid our maps use) into `dir` and the maps above into its stereo/ folders.
// Returns the image names.
std::vector<std::string> WriteExampleWithExactMaps(const std::filesystem::path& dir);

// The ground-truth depth map of `name` in the workspace at `dir`.
colmap_io::DenseArray GroundTruthDepth(const std::filesystem::path& dir, const std::string& name);

// A fixture over that workspace in a temporary folder (ROOT = TEMP/ws), with
// its plan (PlanOptions defaults) and a log for the passes.
class ExactMapsTest : public ::testing::Test {
 protected:
  ::dispmvs::testing::TempDir dir_;
  std::filesystem::path root_ = dir_.path() / "ws";
  // Written before the workspace is opened (it checks its folders).
  std::vector<std::string> names_ = WriteExampleWithExactMaps(root_);
  colmap_io::Workspace workspace_{root_};
  DensePlan plan_ = PlanDenseReconstruction(workspace_, PlanOptions());
  std::ostringstream log_;
};

}  // namespace dispmvs::dense::testing
