// The export for `colmap stereo_fusion`: our maps byte for byte under
// COLMAP's names, the links, the configuration files, and refusals.

#include "dense/colmap_export.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/error.h"
#include "colmap_io/stereo_config.h"
#include "dense/geometric_pass.h"
#include "dense/test_workspace.h"
#include "dense/workspace_maps.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::dense {
namespace {

namespace fs = std::filesystem;

using ::dispmvs::testing::ReadFileBytes;

class ColmapExportTest : public testing::ExactMapsTest {
 protected:
  void SetUp() override {
    RunGeometricPass(workspace_, plan_, {}, log_);
  }

  fs::path export_root_ = dir_.path() / "export";
};

TEST_F(ColmapExportTest, MapsUnderColmapNamesWithSourcesAndLinks) {
  // One view without maps is left out of the export and of fusion.cfg.
  const std::string& left_out = names_[6];
  fs::remove(PathsOf(workspace_, left_out, kPhotometricType).depth);
  fs::remove(PathsOf(workspace_, left_out, kGeometricType).depth);

  EXPECT_EQ(ExportForColmap(workspace_, plan_, export_root_, log_), 6);
  const colmap_io::Workspace exported(export_root_);
  for (const std::string& name : names_) {
    for (const auto& [ours, theirs] : {std::pair<const char*, const char*>{kPhotometricType, "photometric"},
                                       {kGeometricType, "geometric"}}) {
      const fs::path depth = exported.DepthMapPath(name, theirs);
      const fs::path normal = exported.NormalMapPath(name, theirs);
      if (name == left_out) {
        EXPECT_FALSE(fs::exists(depth)) << depth;
        continue;
      }
      EXPECT_EQ(ReadFileBytes(depth), ReadFileBytes(workspace_.DepthMapPath(name, ours))) << depth;
      EXPECT_EQ(ReadFileBytes(normal), ReadFileBytes(workspace_.NormalMapPath(name, ours))) << normal;
    }
  }
  EXPECT_TRUE(fs::is_symlink(export_root_ / "images"));
  EXPECT_TRUE(fs::equivalent(export_root_ / "images", workspace_.ImagesDir()));
  EXPECT_TRUE(fs::is_symlink(export_root_ / "sparse"));
  EXPECT_TRUE(fs::equivalent(export_root_ / "sparse", workspace_.SparseDir()));

  // patch-match.cfg: each exported reference with the plan's sources, by name.
  const auto entries = colmap_io::ReadPatchMatchConfig(exported.PatchMatchConfigPath());
  ASSERT_EQ(entries.size(), 6u);
  for (const auto& entry : entries) {
    const auto* image = plan_.model.FindImageByName(entry.reference);
    ASSERT_NE(image, nullptr) << entry.reference;
    const auto problem = std::find_if(plan_.problems.begin(), plan_.problems.end(), [&](const auto& p) {
      return p.reference_image_id == image->image_id;
    });
    ASSERT_NE(problem, plan_.problems.end());
    std::vector<std::string> sources;
    for (colmap_io::image_t source : problem->source_image_ids) {
      sources.push_back(plan_.ImageOf(source).name);
    }
    EXPECT_EQ(entry.sources, colmap_io::SourceSpec::Explicit(sources)) << entry.reference;
  }
  std::vector<std::string> fused = colmap_io::ReadFusionConfig(exported.FusionConfigPath());
  EXPECT_EQ(fused.size(), 6u);
  EXPECT_EQ(std::find(fused.begin(), fused.end(), left_out), fused.end());
}

TEST_F(ColmapExportTest, RepeatingTheExportGivesTheSameFiles) {
  ASSERT_EQ(ExportForColmap(workspace_, plan_, export_root_, log_), 7);
  const colmap_io::Workspace exported(export_root_);
  const std::string before = ReadFileBytes(exported.PatchMatchConfigPath());
  EXPECT_EQ(ExportForColmap(workspace_, plan_, export_root_, log_), 7);
  EXPECT_EQ(ReadFileBytes(exported.PatchMatchConfigPath()), before);
}

TEST_F(ColmapExportTest, RefusesTheWorkspaceItselfAndForeignLinks) {
  EXPECT_THROW(ExportForColmap(workspace_, plan_, workspace_.root(), log_), std::invalid_argument);
  fs::create_directories(export_root_);
  fs::create_directory_symlink(dir_.path(), export_root_ / "images");
  EXPECT_THROW(ExportForColmap(workspace_, plan_, export_root_, log_), colmap_io::IoError);
}

}  // namespace
}  // namespace dispmvs::dense
