// dispmvs_colmap on images built to break a matcher: constant black,
// constant white, pure noise, and a short repeated pattern (every match
// ambiguous), through all three passes. Whatever the depth maps say, no
// output may hold a NaN or an infinity, and the run must end normally; and
// the flat views (black, white) must fuse next to nothing.

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "examples/example_workspace.h"
#include "tests/support/run_program.h"
#include "tests/support/temp_dir.h"

namespace dispmvs {
namespace {

namespace fs = std::filesystem;

struct AdversarialImages {
  std::string name;
  // The image of view `index` (320x240 BGR, the example's size).
  std::function<cv::Mat(int index)> make;
};

std::vector<AdversarialImages> Kinds() {
  const cv::Size size(320, 240);
  return {
      {"black", [size](int) { return cv::Mat(size, CV_8UC3, cv::Scalar::all(0)); }},
      {"white", [size](int) { return cv::Mat(size, CV_8UC3, cv::Scalar::all(255)); }},
      {"noise",
       [size](int index) {
         cv::Mat image(size, CV_8UC3);
         std::mt19937 random(static_cast<unsigned>(index) + 1);
         for (auto it = image.begin<cv::Vec3b>(); it != image.end<cv::Vec3b>(); ++it) {
           for (int c = 0; c < 3; ++c) (*it)[c] = static_cast<uint8_t>(random() & 0xFF);
         }
         return image;
       }},
      {"repeated_pattern",
       [size](int) {  // 4-pixel stripes and checks, the same in every view
         cv::Mat image(size, CV_8UC3);
         for (int row = 0; row < size.height; ++row) {
           for (int col = 0; col < size.width; ++col) {
             const uint8_t v = ((col / 4) + (row / 4)) % 2 ? 230 : 20;
             image.at<cv::Vec3b>(row, col) = cv::Vec3b(v, v, static_cast<uint8_t>(255 - v));
           }
         }
         return image;
       }},
  };
}

void ExpectAllFinite(const std::vector<float>& values, const std::string& what) {
  std::size_t bad = 0;
  for (float v : values) bad += std::isfinite(v) ? 0 : 1;
  EXPECT_EQ(bad, 0u) << what << ": " << bad << " non-finite values";
}

class AdversarialImagesTest : public ::testing::TestWithParam<AdversarialImages> {};

TEST_P(AdversarialImagesTest, NoNanOrInfInAnyOutput) {
  testing::TempDir dir;
  const fs::path ws = dir.path() / "ws";
  examples::ExampleWorkspaceOptions example;
  example.seed = 1;
  examples::WriteExampleWorkspace(ws, example);
  for (int index = 0; index < 7; ++index) {
    const fs::path image = ws / "images" / ("view_0" + std::to_string(index) + ".png");
    ASSERT_TRUE(cv::imwrite(image.string(), GetParam().make(index)));
  }
  const testing::ProgramRun run = testing::RunProgram(
      dir, DISPMVS_COLMAP_PROGRAM,
      "--workspace_path '" + ws.string() + "' --max_image_size 128 --threads 1");
  ASSERT_EQ(run.status, 0) << run.out << run.err;

  int maps = 0;
  for (const auto& entry : fs::recursive_directory_iterator(ws / "stereo")) {
    const std::string name = entry.path().filename().string();
    if (!entry.is_regular_file() || name.find(".dispmvs.") == std::string::npos) continue;
    ExpectAllFinite(colmap_io::ReadDenseArray(entry.path()).values(), name);
    ++maps;
  }
  EXPECT_EQ(maps, 7 * 3 * 2);  // 7 views x (depth, normal, confidence) x 2 types
  std::vector<float> cloud;
  for (const colmap_io::PlyPoint& point : colmap_io::ReadPlyPoints(ws / "fused.ply")) {
    for (int c = 0; c < 3; ++c) {
      cloud.push_back(point.xyz[c]);
      cloud.push_back(point.normal[c]);
    }
  }
  ExpectAllFinite(cloud, "fused.ply");
  const std::size_t points = cloud.size() / 6;
  std::printf("%s: %zu fused points\n", GetParam().name.c_str(), points);
  // Views without any texture hold no evidence for a depth: their
  // confidence is 0 (model/confidence_model.h), so the default
  // --min_confidence fuses nothing from them. Before the confidence model
  // they fused 1164 (black) and 1267 (white) points here; the bound is 1 %
  // of those.
  if (GetParam().name == "black" || GetParam().name == "white") EXPECT_LT(points, 12u);
}

void PrintTo(const AdversarialImages& kind, std::ostream* out) { *out << kind.name; }

INSTANTIATE_TEST_SUITE_P(Images, AdversarialImagesTest, ::testing::ValuesIn(Kinds()),
                         [](const ::testing::TestParamInfo<AdversarialImages>& info) {
                           return info.param.name;
                         });

}  // namespace
}  // namespace dispmvs
