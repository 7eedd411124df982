// dispmvs_stereo_pair_workspace end to end on a tiny generated pair: --help,
// bad input (one "error: " line, exit status 1), and a workspace that
// dispmvs_eval accepts and scores as a rectified pair.

#include <gtest/gtest.h>

#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "bench/npy_test_util.h"
#include "colmap_io/dense_array.h"
#include "tests/support/run_program.h"
#include "tests/support/temp_dir.h"

#ifndef DISPMVS_STEREO_PAIR_PROGRAM
#error "DISPMVS_STEREO_PAIR_PROGRAM must name the dispmvs_stereo_pair_workspace binary"
#endif
#ifndef DISPMVS_EVAL_PROGRAM
#error "DISPMVS_EVAL_PROGRAM must name the dispmvs_eval binary"
#endif

namespace dispmvs::bench {
namespace {

namespace fs = std::filesystem;
using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::TempDir;
using dispmvs::testing::WriteFileBytes;

constexpr int kWidth = 16, kHeight = 10;
constexpr double kFocal = 20, kDoffs = 1, kBaseline = 0.5;

using dispmvs::testing::ExpectError;
using dispmvs::testing::RunProgram;

std::vector<std::string> Fields(const std::string& line) {
  std::vector<std::string> fields;
  std::istringstream in(line);
  for (std::string field; std::getline(in, field, '\t');) fields.push_back(field);
  return fields;
}

class StereoPairCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    cv::Mat left(kHeight, kWidth, CV_8UC3), right(kHeight, kWidth, CV_8UC3);
    for (int r = 0; r < kHeight; ++r) {
      for (int c = 0; c < kWidth; ++c) {
        left.at<cv::Vec3b>(r, c) = cv::Vec3b(static_cast<uint8_t>(16 * c), 100, static_cast<uint8_t>(20 * r));
        right.at<cv::Vec3b>(r, c) = cv::Vec3b(100, static_cast<uint8_t>(16 * c), 50);
      }
    }
    ASSERT_TRUE(cv::imwrite((dir_.path() / "l.png").string(), left));
    ASSERT_TRUE(cv::imwrite((dir_.path() / "r.png").string(), right));
    // A slanted plane: disparity 2 + 0.05 col, all known.
    std::vector<double> disparity;
    for (int r = 0; r < kHeight; ++r) {
      for (int c = 0; c < kWidth; ++c) disparity.push_back(2 + 0.05 * c);
    }
    WriteFileBytes(dir_.path() / "d.npy", testing::Float32Npy(kHeight, kWidth, disparity));
  }

  std::string Inputs(const std::string& npy = "d.npy") const {
    const fs::path p = dir_.path();
    return "--left '" + (p / "l.png").string() + "' --right '" + (p / "r.png").string() +
           "' --disparity '" + (p / npy).string() + "'";
  }
  static std::string Calibration() {
    return "--focal 20 --cx 8.2 --cy 5.1 --doffs 1 --baseline 0.5";
  }
  std::string Output() const { return "--output_path '" + ws().string() + "'"; }
  fs::path ws() const { return dir_.path() / "ws"; }

  TempDir dir_;
};

TEST_F(StereoPairCliTest, Help) {
  const dispmvs::testing::ProgramRun run = RunProgram(dir_, DISPMVS_STEREO_PAIR_PROGRAM, "--help");
  EXPECT_EQ(run.status, 0);
  EXPECT_NE(run.out.find("Usage: dispmvs_stereo_pair_workspace --left"), std::string::npos);
  EXPECT_NE(run.out.find("depth-range hint"), std::string::npos);
  EXPECT_NE(run.out.find("--num_sparse_points"), std::string::npos);
}

TEST_F(StereoPairCliTest, Errors) {
  const char* program = DISPMVS_STEREO_PAIR_PROGRAM;
  ExpectError(RunProgram(dir_, program, ""), "--left is required");
  ExpectError(RunProgram(dir_, program, Inputs() + " " + Output() + " --focal 20 --cx 1 --cy 1 --doffs 0"),
              "--baseline is required");
  ExpectError(RunProgram(dir_, program, Inputs() + " " + Calibration() + " --focal 0 " + Output()),
              "--focal");
  ExpectError(RunProgram(dir_, program, Inputs() + " " + Output() +
                                     " --focal 20 --cx 1 --cy 1 --doffs 0 --baseline -1"),
              "--baseline must be > 0");
  ExpectError(RunProgram(dir_, program, Inputs() + " " + Output() +
                                     " --focal 20 --cx nan --cy 1 --doffs 0 --baseline 1"),
              "--cx must be finite");
  ExpectError(RunProgram(dir_, program, Inputs() + " " + Output() +
                                     " --focal abc --cx 1 --cy 1 --doffs 0 --baseline 1"),
              "focal");
  ExpectError(RunProgram(dir_, program, Inputs() + " " + Calibration() + " " + Output() +
                                     " --num_sparse_points 0"),
              "--num_sparse_points must be in [1, 10000000]");
  ExpectError(RunProgram(dir_, program, Inputs() + " " + Calibration() + " " + Output() + " --bogus"),
              "bogus");
  WriteFileBytes(dir_.path() / "bad.npy", "not numpy");
  ExpectError(RunProgram(dir_, program, Inputs("bad.npy") + " " + Calibration() + " " + Output()),
              "bad.npy: not a NumPy .npy file");
  WriteFileBytes(dir_.path() / "small.npy",
                 testing::Float32Npy(kHeight, kWidth - 1, std::vector<double>(kHeight * (kWidth - 1), 2.0)));
  ExpectError(RunProgram(dir_, program, Inputs("small.npy") + " " + Calibration() + " " + Output()),
              "small.npy: disparity map is 15x10 (cols x rows) but the left image is 16x10");
  ExpectError(RunProgram(dir_, program, Inputs("none.npy") + " " + Calibration() + " " + Output()),
              "none.npy: no such file");
  EXPECT_FALSE(fs::exists(ws()));
}

TEST_F(StereoPairCliTest, DispmvsEvalScoresTheWorkspaceAsARectifiedPair) {
  const dispmvs::testing::ProgramRun made = RunProgram(dir_, DISPMVS_STEREO_PAIR_PROGRAM,
                             Inputs() + " " + Calibration() + " " + Output() +
                                 " --num_sparse_points 50");
  ASSERT_EQ(made.status, 0) << made.out << made.err;
  EXPECT_EQ(made.err, "");
  // 15 x 9 corners have four known disparities (0.05 px apart at most).
  EXPECT_NE(made.out.find("ground truth: 135 pixels with depth"), std::string::npos) << made.out;
  EXPECT_NE(made.out.find("sparse points: 50 (of "), std::string::npos) << made.out;

  // Maps of the GT depth with the disparity shifted by 0, 0.5 and 1.5 px.
  const colmap_io::DenseArray gt =
      colmap_io::ReadDenseArray(ws() / "ground_truth" / "depth_maps" / "left.png.bin");
  const double focal_baseline = kFocal * kBaseline;
  for (const auto& [type, shift] : {std::pair<const char*, double>{"exact", 0.0},
                                    {"half_px", 0.5}, {"one_and_half_px", 1.5}}) {
    colmap_io::DenseArray map = gt;
    for (std::size_t i = 0; i < map.size(); ++i) {
      const float z = gt.data()[i];
      if (z > 0) map.data()[i] = static_cast<float>(focal_baseline / (focal_baseline / z + shift));
    }
    colmap_io::WriteDenseArray(
        map, ws() / "stereo" / "depth_maps" / ("left.png." + std::string(type) + ".bin"));
  }
  const fs::path tsv = dir_.path() / "eval.tsv";
  const dispmvs::testing::ProgramRun eval = RunProgram(dir_, DISPMVS_EVAL_PROGRAM,
                             "--workspace_path '" + ws().string() +
                                 "' --types exact,half_px,one_and_half_px --tsv '" + tsv.string() +
                                 "'");
  ASSERT_EQ(eval.status, 0) << eval.out << eval.err;
  EXPECT_NE(eval.out.find("depth maps vs ground truth: 1 of 2 images have ground truth"),
            std::string::npos)
      << eval.out;
  EXPECT_NE(eval.out.find("disp_err"), std::string::npos) << eval.out;
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(ReadFileBytes(tsv));
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("depth\t", 0) == 0) rows.push_back(Fields(line));
  }
  ASSERT_EQ(rows.size(), 3u);
  // type, views, gt_pixels, ..., disparity_gt_pixels, <1 px, <2 px.
  const std::vector<std::vector<std::string>> expected = {
      {"exact", "1", "135", "135", "135"},
      {"half_px", "1", "135", "135", "135"},
      {"one_and_half_px", "1", "135", "0", "135"}};
  for (std::size_t i = 0; i < rows.size(); ++i) {
    ASSERT_EQ(rows[i].size(), 12u);
    EXPECT_EQ((std::vector<std::string>{rows[i][1], rows[i][2], rows[i][9], rows[i][10],
                                        rows[i][11]}),
              expected[i]);
    EXPECT_EQ(rows[i][3], "135");  // GT pixels of the depth metrics too
  }
}

}  // namespace
}  // namespace dispmvs::bench
