#include "dense/test_workspace.h"

#include <algorithm>

#include "colmap_io/workspace.h"
#include "dense/workspace_maps.h"
#include "examples/example_workspace.h"

namespace dispmvs::dense::testing {

namespace fs = std::filesystem;

colmap_io::DenseArray GroundTruthDepth(const fs::path& dir, const std::string& name) {
  return colmap_io::ReadDenseArray(dir / "ground_truth" / "depth_maps" / (name + ".bin"));
}

std::vector<std::string> WriteExampleWithExactMaps(const fs::path& dir) {
  examples::ExampleWorkspaceOptions options;
  options.seed = 1;
  options.sampling = examples::GroundTruthSampling::kColmapDenseIndexing;
  examples::WriteExampleWorkspace(dir, options);
  const colmap_io::Workspace workspace(dir);
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(workspace.ImagesDir())) {
    names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  for (const std::string& name : names) {
    const colmap_io::DenseArray depth = GroundTruthDepth(dir, name);
    const colmap_io::DenseArray normal =
        colmap_io::ReadDenseArray(dir / "ground_truth" / "normal_maps" / (name + ".bin"));
    colmap_io::DenseArray confidence(depth.width(), depth.height(), 1, 0.0f);
    for (std::size_t i = 0; i < depth.size(); ++i) {
      confidence.data()[i] = depth.data()[i] > 0 ? 1.0f : 0.0f;
    }
    WriteMaps(PathsOf(workspace, name, kPhotometricType), depth, normal, confidence);
  }
  return names;
}

}  // namespace dispmvs::dense::testing
