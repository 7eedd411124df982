// The geometric pass on exact maps (dense/test_workspace.h): every kept depth
// is the photometric one unchanged, exact maps agree with each other, a map
// 5 % off agrees with none, and a missing map or a raised per-reference
// requirement is honoured.

#include "dense/geometric_pass.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/dense_array.h"
#include "dense/test_workspace.h"
#include "dense/workspace_maps.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::dense {
namespace {

namespace fs = std::filesystem;
using colmap_io::DenseArray;

// Measured on this fixture (pure geometry, no randomness): the smallest share
// of a view's pixels kept is 0.740 with all maps exact, 0.692 with one map 5 %
// off (for the other views), 0.599 with one map missing. Pixels that fewer
// than two sources see (the arc's end views, image borders) are dropped.
constexpr double kMinKeptExact = 0.70;
constexpr double kMinKeptWithOneOff = 0.65;
constexpr double kMinKeptWithOneMissing = 0.55;

class GeometricPassTest : public testing::ExactMapsTest {
 protected:
  DenseArray Map(const std::string& name, const char* type) const {
    return colmap_io::ReadDenseArray(PathsOf(workspace_, name, type).depth);
  }

  // Kept pixels of the geometric map over valid pixels of the photometric one.
  double KeptShare(const std::string& name) const {
    const DenseArray photometric = Map(name, kPhotometricType);
    const DenseArray geometric = Map(name, kGeometricType);
    return ValidFraction(geometric) / ValidFraction(photometric);
  }
};

TEST_F(GeometricPassTest, ExactMapsAgreeAndKeptDepthsAreUnchanged) {
  ASSERT_EQ(names_.size(), 7u);
  const PassSummary summary = RunGeometricPass(workspace_, plan_, {}, log_);
  EXPECT_EQ(summary.done, 7) << log_.str();
  EXPECT_TRUE(summary.failures.empty());
  for (const std::string& name : names_) {
    const DenseArray photometric = Map(name, kPhotometricType);
    const DenseArray geometric = Map(name, kGeometricType);
    ASSERT_EQ(geometric.width(), photometric.width());
    ASSERT_EQ(geometric.height(), photometric.height());
    for (std::size_t i = 0; i < geometric.size(); ++i) {
      const float kept = geometric.data()[i];
      if (kept > 0) {
        ASSERT_EQ(kept, photometric.data()[i]) << name << " pixel " << i;
      }
    }
    EXPECT_GT(KeptShare(name), kMinKeptExact) << name;
    // Normals and confidence are zeroed exactly where the depth was dropped.
    const MapPaths paths = PathsOf(workspace_, name, kGeometricType);
    const DenseArray normal = colmap_io::ReadDenseArray(paths.normal);
    const DenseArray confidence = colmap_io::ReadDenseArray(paths.confidence);
    for (std::size_t i = 0; i < geometric.size(); ++i) {
      const bool kept = geometric.data()[i] > 0;
      ASSERT_EQ(confidence.data()[i] > 0, kept) << name << " pixel " << i;
      ASSERT_EQ(normal.data()[i] != 0 || normal.data()[geometric.size() + i] != 0 ||
                    normal.data()[2 * geometric.size() + i] != 0,
                kept)
          << name << " pixel " << i;
    }
  }
}

TEST_F(GeometricPassTest, MapFivePercentOffAgreesWithNoSource) {
  const std::string& off = names_[3];
  DenseArray depth = Map(off, kPhotometricType);
  for (std::size_t i = 0; i < depth.size(); ++i) depth.data()[i] *= 1.05f;
  colmap_io::WriteDenseArray(depth, PathsOf(workspace_, off, kPhotometricType).depth);

  RunGeometricPass(workspace_, plan_, {}, log_);
  EXPECT_LT(KeptShare(off), 0.01) << log_.str();
  for (const std::string& name : names_) {
    if (name != off) {
      EXPECT_GT(KeptShare(name), kMinKeptWithOneOff) << name;
    }
  }
}

TEST_F(GeometricPassTest, MissingMapIsSkippedAndOthersUseTheRest) {
  const std::string& missing = names_[5];
  fs::remove(PathsOf(workspace_, missing, kPhotometricType).depth);
  const PassSummary summary = RunGeometricPass(workspace_, plan_, {}, log_);
  EXPECT_EQ(summary.done, 6);
  EXPECT_EQ(summary.skipped_no_sources, 1);
  EXPECT_FALSE(fs::exists(PathsOf(workspace_, missing, kGeometricType).depth));
  for (const std::string& name : names_) {
    if (name != missing) {
      EXPECT_GT(KeptShare(name), kMinKeptWithOneMissing) << name;
    }
  }
}

TEST_F(GeometricPassTest, PerReferenceRequirementOverridesTheOption) {
  const std::string& strict = names_[0];
  const colmap_io::image_t id = plan_.model.FindImageByName(strict)->image_id;
  plan_.min_consistent_views[id] = 32;  // more sources than it has
  fusion::GeometricFilterOptions options;
  options.min_consistent_views = 1;
  RunGeometricPass(workspace_, plan_, options, log_);
  EXPECT_EQ(ValidFraction(Map(strict, kGeometricType)), 0.0);
  EXPECT_GT(KeptShare(names_[1]), kMinKeptExact);
}

// A map that cannot be read fails its own view; the views that list it as a
// source go on without it (said in the log), as if it had no map.
TEST_F(GeometricPassTest, UnreadableMapFailsItsViewAndIsLeftOutOfTheOthers) {
  const std::string& broken = names_[0];
  const MapPaths broken_paths = PathsOf(workspace_, broken, kPhotometricType);
  const colmap_io::image_t broken_id = plan_.model.FindImageByName(broken)->image_id;
  std::vector<std::string> readers;
  for (const colmap_io::StereoProblem& problem : plan_.problems) {
    const auto& sources = problem.source_image_ids;
    if (std::find(sources.begin(), sources.end(), broken_id) != sources.end()) {
      readers.push_back(plan_.ImageOf(problem.reference_image_id).name);
    }
  }
  ASSERT_FALSE(readers.empty());

  // What the readers keep when the broken view has no map at all.
  fs::remove(broken_paths.depth);
  ASSERT_EQ(RunGeometricPass(workspace_, plan_, {}, log_).done, 6);
  std::vector<std::string> expected;
  for (const std::string& reader : readers) {
    expected.push_back(
        ::dispmvs::testing::ReadFileBytes(PathsOf(workspace_, reader, kGeometricType).depth));
  }

  ::dispmvs::testing::WriteFileBytes(broken_paths.depth, "2&2&1&garbage");
  std::ostringstream log;
  const PassSummary summary = RunGeometricPass(workspace_, plan_, {}, log);
  ASSERT_EQ(summary.failures.size(), 1u) << log.str();
  EXPECT_EQ(summary.failures[0].rfind(broken + ": ", 0), 0u) << summary.failures[0];
  EXPECT_EQ(summary.done, 6);
  for (std::size_t i = 0; i < readers.size(); ++i) {
    EXPECT_NE(log.str().find("geometric: " + readers[i] + ": source " + broken + " left out: "),
              std::string::npos)
        << log.str();
    EXPECT_EQ(::dispmvs::testing::ReadFileBytes(PathsOf(workspace_, readers[i], kGeometricType).depth),
              expected[i])
        << readers[i];
  }
}

}  // namespace
}  // namespace dispmvs::dense
