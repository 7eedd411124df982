// The photometric pass on the example workspace with the shipped weights at
// 64x48 (accuracy is the end-to-end test's business): maps of the right size
// for every view, resuming computes only what is missing and reproduces it
// bit for bit, and a view whose image cannot be read fails alone.

#include "dense/photometric_pass.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "colmap_io/dense_array.h"
#include "colmap_io/view_record.h"
#include "dense/test_workspace.h"
#include "dense/view_claim.h"
#include "dense/workspace_maps.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::dense {
namespace {

namespace fs = std::filesystem;

using ::dispmvs::testing::ReadFileBytes;

class PhotometricPassTest : public testing::ExactMapsTest {
 protected:
  void SetUp() override {
    for (const std::string& name : names_) {  // start without maps
      const MapPaths paths = PathsOf(workspace_, name, kPhotometricType);
      fs::remove(paths.depth);
      fs::remove(paths.normal);
      fs::remove(paths.confidence);
    }
    options_.estimator.model_path = DISPMVS_TEST_MODEL_PATH;
    options_.estimator.threads = 1;
    options_.max_image_size = 64;
    options_.seed = 3;
  }

  PhotometricOptions options_;
};

TEST_F(PhotometricPassTest, WritesEveryViewAndResumesBitForBit) {
  const PassSummary first = RunPhotometricPass(workspace_, plan_, options_, log_);
  ASSERT_EQ(first.done, 7) << log_.str();
  for (const std::string& name : names_) {
    const MapPaths paths = PathsOf(workspace_, name, kPhotometricType);
    ASSERT_TRUE(paths.AllExist()) << name;
    const colmap_io::DenseArray depth = colmap_io::ReadDenseArray(paths.depth);
    EXPECT_EQ(depth.width(), 64);  // 320x240 brought to --max_image_size 64
    EXPECT_EQ(depth.height(), 48);
    for (float d : depth.values()) ASSERT_TRUE(std::isfinite(d) && d >= 0) << name;
    EXPECT_GT(ValidFraction(depth), 0.5) << name;
    // Its record for the report: the maps' size, the sources, the device and
    // a time no longer than the whole pass's.
    const auto record = colmap_io::ReadViewRecord(colmap_io::ViewRecordPath(workspace_, name));
    ASSERT_TRUE(record.has_value()) << name;
    EXPECT_EQ(record->width, 64);
    EXPECT_EQ(record->height, 48);
    for (const colmap_io::StereoProblem& problem : plan_.problems) {
      if (plan_.ImageOf(problem.reference_image_id).name == name) {
        EXPECT_EQ(record->num_sources, static_cast<int>(problem.source_image_ids.size()));
      }
    }
    EXPECT_EQ(record->device, "cpu");
    EXPECT_GT(record->seconds, 0);
    EXPECT_LE(record->seconds, first.seconds);
  }

  // A finished run resumes instantly.
  const PassSummary again = RunPhotometricPass(workspace_, plan_, options_, log_);
  EXPECT_EQ(again.done, 0);
  EXPECT_EQ(again.skipped_existing, 7);

  // A run killed between writing a view's normal and depth maps left no
  // depth map: only that view is computed again, to the same bytes.
  const MapPaths paths = PathsOf(workspace_, names_[4], kPhotometricType);
  const std::string depth_bytes = ReadFileBytes(paths.depth);
  const std::string normal_bytes = ReadFileBytes(paths.normal);
  fs::remove(paths.depth);
  const PassSummary resumed = RunPhotometricPass(workspace_, plan_, options_, log_);
  EXPECT_EQ(resumed.done, 1);
  EXPECT_EQ(resumed.skipped_existing, 6);
  EXPECT_EQ(ReadFileBytes(paths.depth), depth_bytes);
  EXPECT_EQ(ReadFileBytes(paths.normal), normal_bytes);
}

// A damaged image fails its own view only: the views that list it as a
// source run without it, say so, and record the sources they used; the failed
// view's record says why.
TEST_F(PhotometricPassTest, UnreadableImageFailsItsOwnViewAndIsLeftOutOfTheOthers) {
  const std::string& broken = names_[0];  // an end of the arc: fewer readers
  std::ofstream(workspace_.ImagePath(broken), std::ios::trunc) << "not a PNG";
  const colmap_io::image_t broken_id = plan_.model.FindImageByName(broken)->image_id;
  std::map<std::string, int> sources_left;  // views that read it as a source
  for (const colmap_io::StereoProblem& problem : plan_.problems) {
    const int sources = static_cast<int>(problem.source_image_ids.size());
    for (colmap_io::image_t source : problem.source_image_ids) {
      if (source == broken_id) sources_left[plan_.ImageOf(problem.reference_image_id).name] = sources - 1;
    }
  }
  ASSERT_FALSE(sources_left.empty());

  const PassSummary summary = RunPhotometricPass(workspace_, plan_, options_, log_);
  EXPECT_EQ(summary.done, 6) << log_.str();
  ASSERT_EQ(summary.failures.size(), 1u);
  EXPECT_EQ(summary.failures[0].rfind(broken + ": ", 0), 0u) << summary.failures[0];
  EXPECT_NE(summary.failures[0].find("not an image in a supported format"), std::string::npos);
  EXPECT_FALSE(fs::exists(PathsOf(workspace_, broken, kPhotometricType).depth));
  const auto failed = colmap_io::ReadViewRecord(colmap_io::ViewRecordPath(workspace_, broken));
  ASSERT_TRUE(failed.has_value());
  EXPECT_EQ(failed->failure, summary.failures[0].substr(broken.size() + 2));
  // The reason once, then only the name.
  const std::string reason = "; source " + broken + " left out: " +
                             workspace_.ImagePath(broken).string() + ": not an image";
  const std::string log = log_.str();
  EXPECT_NE(log.find(reason), std::string::npos) << log;
  EXPECT_EQ(log.find(reason, log.find(reason) + 1), std::string::npos) << log;
  for (const auto& [name, sources] : sources_left) {
    EXPECT_TRUE(PathsOf(workspace_, name, kPhotometricType).AllExist()) << name;
    const auto record = colmap_io::ReadViewRecord(colmap_io::ViewRecordPath(workspace_, name));
    ASSERT_TRUE(record.has_value()) << name;
    EXPECT_EQ(record->num_sources, sources) << name;
    const std::size_t line = log.find("] " + name + " (");
    ASSERT_NE(line, std::string::npos) << log;
    EXPECT_NE(log.substr(line, log.find('\n', line) - line).find("; source " + broken + " left out: "),
              std::string::npos)
        << name;
  }
}

// A view claimed by another process (here: this test, holding its lock) is
// skipped and said so; once released, a rerun computes just that view and
// clears what its holder left.
TEST_F(PhotometricPassTest, SkipsAViewAnotherProcessHasClaimed) {
  const std::string& held = names_[2];
  std::optional<ViewClaim> claim = ViewClaim::TryClaim(ClaimPath(workspace_, held));
  ASSERT_TRUE(claim.has_value());
  // The holder's temporaries, as it writes (or as it left them, killed):
  // untouched while it holds the view, removed by the run that claims it next.
  const MapPaths held_paths = PathsOf(workspace_, held, kPhotometricType);
  const std::vector<fs::path> temporaries = {
      held_paths.depth.string() + ".tmp-999999-0", held_paths.normal.string() + ".tmp-999999-1",
      colmap_io::ViewRecordPath(workspace_, held).string() + ".tmp-999999-2"};
  for (const fs::path& path : temporaries) {
    fs::create_directories(path.parent_path());
    std::ofstream(path) << "partial";
  }
  const PassSummary first = RunPhotometricPass(workspace_, plan_, options_, log_);
  EXPECT_EQ(first.done, 6) << log_.str();
  EXPECT_EQ(first.skipped_claimed, 1);
  EXPECT_TRUE(first.failures.empty());
  EXPECT_FALSE(fs::exists(PathsOf(workspace_, held, kPhotometricType).depth));
  for (const fs::path& path : temporaries) EXPECT_TRUE(fs::exists(path)) << path;
  EXPECT_NE(log_.str().find(held + " (4 sources): skipped, another process (pid " +
                            std::to_string(::getpid()) + ") is computing it"),
            std::string::npos)
      << log_.str();

  claim.reset();
  const PassSummary second = RunPhotometricPass(workspace_, plan_, options_, log_);
  EXPECT_EQ(second.done, 1);
  EXPECT_EQ(second.skipped_existing, 6);
  EXPECT_EQ(second.skipped_claimed, 0);
  EXPECT_TRUE(PathsOf(workspace_, held, kPhotometricType).AllExist());
  for (const fs::path& path : temporaries) EXPECT_FALSE(fs::exists(path)) << path;
  EXPECT_NE(log_.str().find("(3 temporary file(s) of an interrupted run removed)"),
            std::string::npos)
      << log_.str();
}

// A run killed after a view's maps and before its record committed leaves
// the record's temporary; the view is complete, so the next run skips it
// and clears that file, unless another process holds the view.
TEST_F(PhotometricPassTest, ClearsRecordTemporariesOfCompleteViews) {
  const PassSummary first = RunPhotometricPass(workspace_, plan_, options_, log_);
  ASSERT_EQ(first.done, 7) << log_.str();
  const std::string& cleared = names_[1];
  const std::string& held = names_[4];
  const fs::path cleared_temporary =
      colmap_io::ViewRecordPath(workspace_, cleared).string() + ".tmp-999999-7";
  const fs::path held_temporary =
      colmap_io::ViewRecordPath(workspace_, held).string() + ".tmp-999999-8";
  for (const fs::path& path : {cleared_temporary, held_temporary}) std::ofstream(path) << "partial";
  std::optional<ViewClaim> claim = ViewClaim::TryClaim(ClaimPath(workspace_, held));
  ASSERT_TRUE(claim.has_value());

  log_.str("");
  const PassSummary second = RunPhotometricPass(workspace_, plan_, options_, log_);
  EXPECT_EQ(second.skipped_existing, 7);
  EXPECT_FALSE(fs::exists(cleared_temporary));
  EXPECT_TRUE(fs::exists(held_temporary));
  EXPECT_TRUE(fs::exists(colmap_io::ViewRecordPath(workspace_, cleared)));  // the record stays
  EXPECT_NE(log_.str().find("photometric: 1 temporary record file(s) of an interrupted run removed"),
            std::string::npos)
      << log_.str();

  claim.reset();
  EXPECT_EQ(RemoveRecordLeftovers(workspace_, names_), 1);
  EXPECT_FALSE(fs::exists(held_temporary));
  EXPECT_EQ(RemoveRecordLeftovers(workspace_, names_), 0);
}

TEST(ViewSeedTest, DependsOnRunSeedAndImageOnly) {
  std::set<uint64_t> seeds;
  for (uint64_t run : {0u, 1u, 2u}) {
    for (colmap_io::image_t image = 1; image <= 100; ++image) {
      EXPECT_EQ(ViewSeed(run, image), ViewSeed(run, image));
      seeds.insert(ViewSeed(run, image));
    }
  }
  EXPECT_EQ(seeds.size(), 300u);
}

}  // namespace
}  // namespace dispmvs::dense
