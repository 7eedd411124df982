// Several dispmvs_colmap processes on one workspace at once: shards run
// together, one of them started twice by mistake, give byte-identical
// results to a single process, with every view computed exactly once; and a
// view another process holds is skipped with a message that says so; the
// geometric pass and fusion run in one process at a time.

#include <unistd.h>

#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <regex>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/workspace.h"
#include "dense/test_workspace.h"
#include "dense/view_claim.h"
#include "examples/example_workspace.h"
#include "tests/support/temp_dir.h"
#include "tests/support/watched_process.h"
#include "tests/support/workspace_outputs.h"

namespace dispmvs {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;
using testing::WatchedProcess;

// Outputs under their final names, without the report (it names the
// workspace's path, which differs between the runs compared).
std::map<std::string, std::string> Outputs(const fs::path& root) {
  std::map<std::string, std::string> files = testing::FinalOutputs(root);
  files.erase("dispmvs_report.html");
  return files;
}

std::vector<std::string> Args(const fs::path& ws, const std::string& mode,
                              const std::string& shard = "") {
  std::vector<std::string> args = {"--workspace_path", ws.string(), "--mode", mode,
                                   "--max_image_size", "64", "--threads", "1", "--seed", "3"};
  if (!shard.empty()) {
    args.push_back("--shard");
    args.push_back(shard);
  }
  return args;
}

int RunToEnd(const std::vector<std::string>& args, const fs::path& log, std::string* output) {
  WatchedProcess run(DISPMVS_COLMAP_PROGRAM, args, log);
  const int status = run.Wait();
  *output = run.Output();
  return status;
}

// "summary: photometric: N done" of a run's output.
int ViewsDone(const std::string& output) {
  std::smatch match;
  if (!std::regex_search(output, match, std::regex("summary: photometric: ([0-9]+) done"))) {
    ADD_FAILURE() << "no photometric summary in:\n" << output;
    return -1;
  }
  return std::stoi(match[1]);
}

TEST(ConcurrencyTest, ShardsAtOnceAndADuplicateGiveTheSingleProcessBytes) {
  TempDir dir;
  const fs::path single = dir.path() / "single", shared = dir.path() / "shared";
  examples::ExampleWorkspaceOptions example;
  example.seed = 1;
  examples::WriteExampleWorkspace(single, example);
  examples::WriteExampleWorkspace(shared, example);
  std::string output;
  ASSERT_EQ(RunToEnd(Args(single, "full"), dir.path() / "single.log", &output), 0) << output;
  const auto expected = Outputs(single);
  ASSERT_EQ(expected.count("fused.ply"), 1u);

  // Shard 0/2 twice and shard 1/2, all started at once.
  std::vector<std::unique_ptr<WatchedProcess>> runs;
  for (const char* shard : {"0/2", "1/2", "0/2"}) {
    runs.push_back(std::make_unique<WatchedProcess>(
        DISPMVS_COLMAP_PROGRAM, Args(shared, "photometric", shard),
        dir.path() / ("shard" + std::to_string(runs.size()) + ".log")));
  }
  int done = 0;
  for (auto& run : runs) {
    EXPECT_EQ(run->Wait(), 0) << run->Output();
    done += ViewsDone(run->Output());
  }
  EXPECT_EQ(done, 7) << "each view computed exactly once";
  ASSERT_EQ(RunToEnd(Args(shared, "fuse"), dir.path() / "fuse.log", &output), 0) << output;
  EXPECT_EQ(Outputs(shared), expected);
}

TEST(ConcurrencyTest, AViewAnotherProcessHoldsIsSkippedAndSaidSo) {
  TempDir dir;
  const fs::path ws = dir.path() / "ws";
  examples::ExampleWorkspaceOptions example;
  example.seed = 1;
  examples::WriteExampleWorkspace(ws, example);
  // This test plays the other process: it holds view_03.png's claim.
  std::optional<dense::ViewClaim> claim =
      dense::ViewClaim::TryClaim(dense::ClaimPath(colmap_io::Workspace(ws), "view_03.png"));
  ASSERT_TRUE(claim.has_value());

  std::string output;
  ASSERT_EQ(RunToEnd(Args(ws, "photometric"), dir.path() / "first.log", &output), 0) << output;
  EXPECT_NE(output.find("view_03.png (4 sources): skipped, another process (pid " +
                        std::to_string(::getpid()) + ") is computing it"),
            std::string::npos)
      << output;
  EXPECT_NE(output.find("summary: photometric: 6 done, 0 skipped (existing), 0 skipped (no "
                        "sources or input), 1 skipped (another process was computing them), 0 "
                        "failed"),
            std::string::npos)
      << output;
  EXPECT_NE(output.find("warning: 1 view(s) were being computed by another process"),
            std::string::npos)
      << output;
  EXPECT_FALSE(fs::exists(ws / "stereo" / "depth_maps" / "view_03.png.dispmvs.photometric.bin"));

  claim.reset();  // the other process ended
  ASSERT_EQ(RunToEnd(Args(ws, "photometric"), dir.path() / "second.log", &output), 0) << output;
  EXPECT_EQ(ViewsDone(output), 1) << output;
  EXPECT_TRUE(fs::exists(ws / "stereo" / "depth_maps" / "view_03.png.dispmvs.photometric.bin"));
}

TEST(ConcurrencyTest, FusionAnotherProcessHoldsIsNotRunAndTheExitSaysSo) {
  TempDir dir;
  const fs::path ws = dir.path() / "ws";
  dense::testing::WriteExampleWithExactMaps(ws);
  const std::vector<std::string> fuse = {"--workspace_path", ws.string(), "--mode", "fuse"};
  // This test plays the other process: it holds the fusion claim.
  std::optional<dense::ViewClaim> claim =
      dense::ViewClaim::TryClaim(dense::FusionClaimPath(colmap_io::Workspace(ws)));
  ASSERT_TRUE(claim.has_value());

  std::string output;
  EXPECT_EQ(RunToEnd(fuse, dir.path() / "first.log", &output), 1) << output;
  EXPECT_NE(output.find("error: the geometric pass and fusion were not run: another process (pid " +
                        std::to_string(::getpid()) + ") is running them on this workspace"),
            std::string::npos)
      << output;
  EXPECT_EQ(output.find("summary: geometric"), std::string::npos) << output;
  EXPECT_FALSE(fs::exists(ws / "fused.ply"));
  EXPECT_FALSE(fs::exists(ws / "stereo" / "depth_maps" / "view_03.png.dispmvs.geometric.bin"));

  claim.reset();  // the other process ended
  ASSERT_EQ(RunToEnd(fuse, dir.path() / "second.log", &output), 0) << output;
  EXPECT_TRUE(fs::exists(ws / "fused.ply"));
}

}  // namespace
}  // namespace dispmvs
