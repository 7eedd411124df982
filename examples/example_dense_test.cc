// End to end: dispmvs_colmap (the real program, with the shipped weights) on
// the example workspace, scored against the exact ground truth; and an
// interrupted run that resumes to the same maps as an uninterrupted one.
//
// The thresholds are set from measured results of the shipped model (see the
// comments at each): they catch regressions of the pipeline (geometry,
// conventions, filtering, fusion) and of the model, not loosened to pass.

#include <signal.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/workspace.h"
#include "examples/example_workspace.h"
#include "examples/surface_distance.h"
#include "fusion/vis_file.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::examples {
namespace {

namespace fs = std::filesystem;
using colmap_io::DenseArray;

constexpr uint64_t kSeed = 1;
constexpr int kNumImages = 7;

fs::path MakeExample(const fs::path& root) {
  ExampleWorkspaceOptions options;
  options.seed = kSeed;
  options.sampling = GroundTruthSampling::kColmapDenseIndexing;  // our maps' indexing
  WriteExampleWorkspace(root, options);
  return root;
}

// Runs dispmvs_colmap with `arguments`; output to `log`. Returns the exit status.
int RunProgram(const std::string& arguments, const fs::path& log) {
  const std::string command = std::string("'") + DISPMVS_COLMAP_PROGRAM + "' " + arguments +
                              " > '" + log.string() + "' 2>&1";
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

struct DepthScore {
  std::size_t gt_pixels = 0, predicted = 0, within1 = 0, within2 = 0, within5 = 0;
  double Coverage() const { return static_cast<double>(predicted) / gt_pixels; }
  // Fractions of all ground-truth pixels.
  double Within(std::size_t n) const { return static_cast<double>(n) / gt_pixels; }
};

void AddScore(const DenseArray& map, const DenseArray& gt, DepthScore* score) {
  ASSERT_EQ(map.width(), gt.width());
  ASSERT_EQ(map.height(), gt.height());
  for (std::size_t i = 0; i < gt.size(); ++i) {
    const float d = map.data()[i], g = gt.data()[i];
    ASSERT_TRUE(std::isfinite(d) && d >= 0) << "map value " << d;
    if (!(g > 0)) continue;
    ++score->gt_pixels;
    if (!(d > 0)) continue;
    ++score->predicted;
    const double error = std::abs(d - g) / g;
    score->within1 += error < 0.01;
    score->within2 += error < 0.02;
    score->within5 += error < 0.05;
  }
}

class ExampleDenseTest : public ::testing::Test {
 protected:
  // The run itself is a ctest fixture (example_dense_run in CMakeLists.txt),
  // shared by the tests of this suite, each of which ctest runs as its own
  // process: DISPMVS_DENSE_EXAMPLE names the workspace, its log is
  // WORKSPACE.log. Without the variable (running the binary by hand) the
  // suite makes its own run.
  static void SetUpTestSuite() {
    if (const char* prepared = std::getenv("DISPMVS_DENSE_EXAMPLE")) {
      root_ = prepared;
      const fs::path log = root_.string() + ".log";
      status_ = fs::exists(root_ / "fused.ply") && fs::exists(log) ? 0 : -1;
      if (status_ == 0) log_ = testing::ReadFileBytes(log);
      return;
    }
    dir_ = new testing::TempDir();
    root_ = MakeExample(dir_->path() / "ws");
    const fs::path log = root_.string() + ".log";
    status_ = RunProgram("--workspace_path '" + root_.string() + "'", log);
    log_ = testing::ReadFileBytes(log);
    std::cout << log_;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }

  static DepthScore Score(const std::string& type) {
    const colmap_io::Workspace workspace(root_);
    DepthScore score;
    for (const auto& [image_id, image] : workspace.ReadModel().images) {
      const DenseArray map = colmap_io::ReadDenseArray(workspace.DepthMapPath(image.name, type));
      const DenseArray gt =
          colmap_io::ReadDenseArray(root_ / "ground_truth" / "depth_maps" / (image.name + ".bin"));
      AddScore(map, gt, &score);
    }
    std::cout << type << ": coverage " << score.Coverage() << ", <1% " << score.Within(score.within1)
              << ", <2% " << score.Within(score.within2) << ", <5% " << score.Within(score.within5)
              << " (fractions of ground-truth pixels)\n";
    return score;
  }

  static testing::TempDir* dir_;
  static fs::path root_;
  static int status_;
  static std::string log_;
};


testing::TempDir* ExampleDenseTest::dir_ = nullptr;
fs::path ExampleDenseTest::root_;
int ExampleDenseTest::status_ = -1;
std::string ExampleDenseTest::log_;

TEST_F(ExampleDenseTest, RunsEveryPassAndSummarises) {
  ASSERT_EQ(status_, 0) << log_;
  EXPECT_NE(log_.find("summary: photometric: 7 done, 0 skipped (existing)"), std::string::npos);
  EXPECT_NE(log_.find("summary: geometric: 7 done"), std::string::npos);
  EXPECT_NE(log_.find("summary: fusion: "), std::string::npos);
  EXPECT_NE(log_.find("ETA"), std::string::npos);
}

TEST_F(ExampleDenseTest, NormalAndConfidenceMapsAreWellFormed) {
  ASSERT_EQ(status_, 0) << log_;
  const colmap_io::Workspace workspace(root_);
  const colmap_io::SparseModel model = workspace.ReadModel();
  for (const auto& [image_id, image] : model.images) {
    // The maps are at full size: COLMAP's dense convention X = d K^-1 (col, row, 1).
    const Eigen::Matrix3d K_inverse = model.cameras.at(image.camera_id).CalibrationMatrix().inverse();
    const DenseArray depth =
        colmap_io::ReadDenseArray(workspace.DepthMapPath(image.name, "dispmvs.photometric"));
    const DenseArray normal =
        colmap_io::ReadDenseArray(workspace.NormalMapPath(image.name, "dispmvs.photometric"));
    const DenseArray confidence =
        colmap_io::ReadDenseArray(workspace.ConfidenceMapPath(image.name, "dispmvs.photometric"));
    ASSERT_EQ(normal.channels(), 3);
    ASSERT_EQ(normal.width(), depth.width());
    ASSERT_EQ(confidence.width(), depth.width());
    const std::size_t plane = depth.size();
    std::size_t with_normal = 0;
    for (std::size_t i = 0; i < plane; ++i) {
      const float c = confidence.data()[i];
      ASSERT_TRUE(c >= 0 && c <= 1) << c;
      const double nx = normal.data()[i], ny = normal.data()[plane + i],
                   nz = normal.data()[2 * plane + i];
      const double length = std::sqrt(nx * nx + ny * ny + nz * nz);
      if (length == 0) continue;
      ++with_normal;
      ASSERT_NEAR(length, 1.0, 1e-5);
      ASSERT_GT(depth.data()[i], 0) << "normal without depth";
      const int row = static_cast<int>(i) / depth.width(), col = static_cast<int>(i) % depth.width();
      const Eigen::Vector3d ray = K_inverse * Eigen::Vector3d(col, row, 1);
      ASSERT_LT(Eigen::Vector3d(nx, ny, nz).dot(ray), 0)
          << "normals point towards the camera (n . X < 0 in the camera frame)";
    }
    EXPECT_GT(with_normal, plane / 2) << image.name;
  }
}

// Bounds measured with the shipped model (examples/CMakeLists.txt, models/README.md).
TEST_F(ExampleDenseTest, GeometricMapsMatchTheGroundTruth) {
  ASSERT_EQ(status_, 0) << log_;
  const DepthScore photometric = Score("dispmvs.photometric");
  const DepthScore geometric = Score("dispmvs.geometric");
  // Filtering keeps the accurate part: a higher share of the kept pixels is
  // within 2 % than of the raw photometric pixels.
  EXPECT_GT(static_cast<double>(geometric.within2) / geometric.predicted,
            static_cast<double>(photometric.within2) / photometric.predicted);
  EXPECT_GT(photometric.Within(photometric.within5), DISPMVS_E2E_MIN_PHOTOMETRIC_WITHIN5);
  EXPECT_GT(geometric.Coverage(), DISPMVS_E2E_MIN_GEOMETRIC_COVERAGE);
  EXPECT_GT(static_cast<double>(geometric.within2) / geometric.predicted,
            DISPMVS_E2E_MIN_GEOMETRIC_WITHIN2);
}

TEST_F(ExampleDenseTest, FusedCloudLiesOnTheSurfacesWithVisibility) {
  ASSERT_EQ(status_, 0) << log_;
  const auto points = colmap_io::ReadPlyPoints(root_ / "fused.ply");
  const auto visibility = fusion::ReadVisibilityFile(root_ / "fused.ply.vis");
  ASSERT_EQ(points.size(), visibility.size());
  ASSERT_GT(points.size(), 1000u);
  std::vector<Eigen::Vector3d> positions;
  for (std::size_t i = 0; i < points.size(); ++i) {
    positions.emplace_back(points[i].xyz[0], points[i].xyz[1], points[i].xyz[2]);
    // The reference and at least --min_num_consistent (2) sources.
    ASSERT_GE(visibility[i].size(), 3u);
    for (uint32_t index : visibility[i]) ASSERT_LT(index, static_cast<uint32_t>(kNumImages));
  }
  const colmap_io::Workspace workspace(root_);
  const std::vector<double> distances =
      SortedSurfaceDistances(positions, workspace.ReadModel());
  const double median = distances[distances.size() / 2];
  const double p90 = distances[distances.size() * 9 / 10];
  std::cout << "fused points: " << points.size() << ", surface distance median " << median
            << ", p90 " << p90 << " (scene depths 3 to 10)\n";
  EXPECT_LT(median, DISPMVS_E2E_MAX_FUSED_MEDIAN_DISTANCE);
  EXPECT_LT(p90, DISPMVS_E2E_MAX_FUSED_P90_DISTANCE);
}

TEST_F(ExampleDenseTest, ASecondRunSkipsEveryViewAndGivesTheSameCloud) {
  ASSERT_EQ(status_, 0) << log_;
  const std::string before = testing::ReadFileBytes(root_ / "fused.ply");
  const fs::path log = root_.string() + ".rerun.log";
  ASSERT_EQ(RunProgram("--workspace_path '" + root_.string() + "'", log), 0);
  const std::string text = testing::ReadFileBytes(log);
  EXPECT_NE(text.find("summary: photometric: 0 done, 7 skipped (existing)"), std::string::npos)
      << text;
  EXPECT_EQ(testing::ReadFileBytes(root_ / "fused.ply"), before);
}

// Every map file under stereo/ by its final name, sorted.
std::vector<fs::path> MapFiles(const fs::path& root) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(root / "stereo")) {
    if (entry.is_regular_file() && entry.path().extension() == ".bin") {
      files.push_back(fs::relative(entry.path(), root));
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

TEST(ExampleDenseResumeTest, AKilledRunResumesToTheMapsOfAnUninterruptedOne) {
  testing::TempDir dir;
  const fs::path whole = MakeExample(dir.path() / "whole");
  const fs::path killed = MakeExample(dir.path() / "killed");
  const std::string common = " --mode photometric --threads 1";
  ASSERT_EQ(RunProgram("--workspace_path '" + whole.string() + "'" + common,
                       dir.path() / "whole.log"),
            0);

  // Start the same run and kill it (SIGKILL: no chance to clean up) as soon
  // as its first view is complete.
  const fs::path first = colmap_io::Workspace(killed).DepthMapPath("view_00.png",
                                                                    "dispmvs.photometric");
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const std::string workspace = killed.string();
    const int log = ::open((dir.path() / "killed.log").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (log >= 0) {
      ::dup2(log, 1);
      ::dup2(log, 2);
    }
    ::execl(DISPMVS_COLMAP_PROGRAM, DISPMVS_COLMAP_PROGRAM, "--workspace_path", workspace.c_str(),
            "--mode", "photometric", "--threads", "1", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(5);
  while (!fs::exists(first) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(fs::exists(first)) << testing::ReadFileBytes(dir.path() / "killed.log");

  // Whatever exists under a final name is complete (the reader checks the
  // size against the header); the run was cut short.
  const std::vector<fs::path> partial = MapFiles(killed);
  for (const fs::path& file : partial) {
    EXPECT_NO_THROW(colmap_io::ReadDenseArray(killed / file)) << file;
  }
  ASSERT_LT(partial.size(), MapFiles(whole).size()) << "the run finished before it was killed";

  const fs::path log = dir.path() / "resumed.log";
  ASSERT_EQ(RunProgram("--workspace_path '" + killed.string() + "'" + common, log), 0);
  const std::string text = testing::ReadFileBytes(log);
  EXPECT_EQ(text.find(" 0 skipped (existing)"), std::string::npos) << "nothing was resumed:\n"
                                                                    << text;
  ASSERT_EQ(MapFiles(killed), MapFiles(whole));
  for (const fs::path& file : MapFiles(whole)) {
    EXPECT_EQ(testing::ReadFileBytes(killed / file), testing::ReadFileBytes(whole / file)) << file;
  }
}

}  // namespace
}  // namespace dispmvs::examples
