// The run report on the example workspace: every picture it embeds decodes
// to an image of the promised size, the table has PatchMatch's columns only
// when PatchMatch's maps exist, coverage is printed per map, and the cloud
// section follows the cloud.

#include "eval/html_report.h"

#include <cstdint>
#include <filesystem>
#include <regex>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "colmap_io/view_record.h"
#include "colmap_io/workspace.h"
#include "examples/example_workspace.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::eval {
namespace {

namespace fs = std::filesystem;

// Standard base64 (RFC 4648), written here independently of the report's encoder.
std::vector<uchar> DecodeBase64(const std::string& text) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    return c == '+' ? 62 : c == '/' ? 63 : -1;
  };
  std::vector<uchar> out;
  uint32_t bits = 0;
  int count = 0;
  for (char c : text) {
    if (c == '=') break;
    const int v = value(c);
    if (v < 0) ADD_FAILURE() << "not base64: " << c;
    bits = (bits << 6) | static_cast<uint32_t>(v);
    count += 6;
    if (count >= 8) {
      count -= 8;
      out.push_back(static_cast<uchar>((bits >> count) & 0xFF));
    }
  }
  return out;
}

class HtmlReportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    examples::ExampleWorkspaceOptions options;
    options.seed = 1;
    options.sampling = examples::GroundTruthSampling::kColmapDenseIndexing;
    examples::WriteExampleWorkspace(root_, options);
    const colmap_io::Workspace workspace(root_);
    for (int i = 0; i < 7; ++i) {
      const std::string name = "view_0" + std::to_string(i) + ".png";
      const colmap_io::DenseArray depth =
          colmap_io::ReadDenseArray(root_ / "ground_truth" / "depth_maps" / (name + ".bin"));
      colmap_io::WriteDenseArray(depth, workspace.DepthMapPath(name, "dispmvs.photometric"));
      colmap_io::WriteDenseArray(colmap_io::DenseArray(320, 240, 1, 1.0f),
                                 workspace.ConfidenceMapPath(name, "dispmvs.photometric"));
    }
  }

  // (width, height) of every embedded picture, in page order.
  static std::vector<cv::Size> Pictures(const std::string& html) {
    std::vector<cv::Size> sizes;
    const std::regex image("<img [^>]*src=\"data:image/jpeg;base64,([A-Za-z0-9+/=]+)\"");
    for (auto it = std::sregex_iterator(html.begin(), html.end(), image);
         it != std::sregex_iterator(); ++it) {
      const cv::Mat decoded = cv::imdecode(DecodeBase64((*it)[1].str()), cv::IMREAD_COLOR);
      EXPECT_FALSE(decoded.empty());
      sizes.push_back(decoded.size());
    }
    return sizes;
  }

  ::dispmvs::testing::TempDir dir_;
  fs::path root_ = dir_.path() / "ws";
};

TEST_F(HtmlReportTest, PicturesDecodeAtThumbnailSize) {
  const fs::path html_path = dir_.path() / "report.html";
  HtmlReportOptions options;
  options.settings = "dispmvs_colmap --workspace_path <ws> & more";
  const HtmlReportSummary summary = WriteHtmlReport(root_, html_path, options);
  const std::string html = ::dispmvs::testing::ReadFileBytes(html_path);
  EXPECT_EQ(summary.views, 7);
  EXPECT_EQ(summary.bytes, html.size());
  // Per view: image, colour bar, photometric depth, confidence (no geometric
  // map, no normals, no cloud, no PatchMatch).
  const std::vector<cv::Size> pictures = Pictures(html);
  ASSERT_EQ(static_cast<int>(pictures.size()), summary.embedded_images);
  EXPECT_EQ(summary.embedded_images, 7 * 4);
  for (const cv::Size& size : pictures) {
    EXPECT_EQ(size.width, 160);
    EXPECT_TRUE(size.height == 120 || size.height == 10) << size;  // 320x240 scaled, or the bar
  }
  EXPECT_EQ(html.find("PatchMatch"), std::string::npos);
  EXPECT_NE(html.find("320x240, 100.0%"), std::string::npos);
  EXPECT_NE(html.find("No fused cloud"), std::string::npos);
  EXPECT_NE(html.find("&lt;ws&gt; &amp; more"), std::string::npos);  // escaped
  EXPECT_LT(html.size() / summary.embedded_images, 12000u);  // small thumbnails
  EXPECT_NE(html.find("No view has a recorded time"), std::string::npos);
}

TEST_F(HtmlReportTest, TimePerViewAndInAllFromTheViewRecords) {
  const colmap_io::Workspace workspace(root_);
  const double seconds[] = {1.5, 0.25, 2.0};
  for (int i = 0; i < 3; ++i) {
    colmap_io::ViewRecord record;
    record.seconds = seconds[i];
    record.width = 320;
    record.height = 240;
    record.num_sources = 4 - i;
    record.device = "cpu";
    colmap_io::WriteViewRecord(
        colmap_io::ViewRecordPath(workspace, "view_0" + std::to_string(i) + ".png"), record);
  }
  // A damaged record counts as none.
  ::dispmvs::testing::WriteFileBytes(colmap_io::ViewRecordPath(workspace, "view_03.png"),
                                     "seconds 9\nsize 3");
  const fs::path html_path = dir_.path() / "report.html";
  WriteHtmlReport(root_, html_path, HtmlReportOptions());
  const std::string html = ::dispmvs::testing::ReadFileBytes(html_path);
  EXPECT_NE(html.find(": 3 view(s), 3.75 s in all, 1.25 s per view on average, slowest "
                      "view_02.png (2.00 s)."),
            std::string::npos);
  // In each timed view's row, after its name.
  auto row_of = [&html](const std::string& name) {
    const std::size_t start = html.find("<td class=\"name\">" + name);
    return start == std::string::npos ? std::string()
                                      : html.substr(start, html.find("</tr>", start) - start);
  };
  EXPECT_NE(row_of("view_00.png").find("1.50 s, 4 source(s), cpu"), std::string::npos);
  EXPECT_NE(row_of("view_01.png").find("0.25 s, 3 source(s), cpu"), std::string::npos);
  EXPECT_NE(row_of("view_02.png").find("2.00 s, 2 source(s), cpu"), std::string::npos);
  EXPECT_EQ(row_of("view_03.png").find(" source(s), "), std::string::npos);
  EXPECT_EQ(html.find("9.00 s"), std::string::npos);
}

TEST_F(HtmlReportTest, AFailedViewShowsItsReasonAndADamagedImageIsNoPicture) {
  const colmap_io::Workspace workspace(root_);
  colmap_io::ViewRecord failed;
  failed.failure = "ws/images/view_04.png: JPEG file is truncated <cut>";
  colmap_io::WriteViewRecord(colmap_io::ViewRecordPath(workspace, "view_04.png"), failed);
  // Not an image at all: the report goes on without its picture.
  ::dispmvs::testing::WriteFileBytes(root_ / "images" / "view_04.png", "\x89PNG\r\n)\n");
  const fs::path html_path = dir_.path() / "report.html";
  const HtmlReportSummary summary = WriteHtmlReport(root_, html_path, HtmlReportOptions());
  const std::string html = ::dispmvs::testing::ReadFileBytes(html_path);
  const std::size_t row = html.find("<td class=\"name\">view_04.png");
  ASSERT_NE(row, std::string::npos);
  const std::string cells = html.substr(row, html.find("</tr>", row) - row);
  EXPECT_NE(cells.find("(image unreadable)"), std::string::npos);
  EXPECT_NE(cells.find("FAILED: ws/images/view_04.png: JPEG file is truncated &lt;cut&gt;"),
            std::string::npos);
  EXPECT_EQ(summary.embedded_images, 7 * 4 - 1);
  EXPECT_NE(html.find("No view has a recorded time"), std::string::npos);  // a failure has none
}

TEST_F(HtmlReportTest, PatchMatchMapsAndTheCloudWhenPresent) {
  const colmap_io::Workspace workspace(root_);
  // PatchMatch's geometric map for one view, half covered.
  colmap_io::DenseArray theirs(320, 240, 1, 0.0f);
  for (int row = 0; row < 120; ++row) {
    for (int col = 0; col < 320; ++col) theirs.at(row, col) = 5.0f;
  }
  colmap_io::WriteDenseArray(theirs, workspace.DepthMapPath("view_03.png", "geometric"));
  std::vector<colmap_io::PlyPoint> cloud(500);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    cloud[i].xyz = {static_cast<float>(i % 25), static_cast<float>(i / 25), 0.1f * (i % 3)};
    cloud[i].rgb = {200, 100, 50};
  }
  colmap_io::WritePlyPoints(cloud, root_ / "fused.ply");
  std::filesystem::remove(workspace.DepthMapPath("view_06.png", "dispmvs.photometric"));
  HtmlReportOptions options;
  options.cloud_view_size = 200;
  const fs::path html_path = dir_.path() / "report.html";
  const HtmlReportSummary summary = WriteHtmlReport(root_, html_path, options);
  const std::string html = ::dispmvs::testing::ReadFileBytes(html_path);
  // Cloud views (three along its axes, one from the first image's camera);
  // per view with maps (view_06 has none left): image, bar, depth,
  // confidence; PatchMatch's map of view_03.
  EXPECT_EQ(summary.embedded_images, 4 + 6 * 4 + 1);
  EXPECT_NE(html.find("from the camera of view_00.png"), std::string::npos);
  EXPECT_NE(html.find("1 registered image(s) without any depth map are not listed"),
            std::string::npos);
  EXPECT_EQ(html.find("view_06.png"), std::string::npos);
  EXPECT_NE(html.find("PatchMatch geometric"), std::string::npos);
  EXPECT_NE(html.find("320x240, 50.0%"), std::string::npos);
  EXPECT_NE(html.find("500 points"), std::string::npos);
  const std::vector<cv::Size> pictures = Pictures(html);
  ASSERT_GE(pictures.size(), 4u);
  for (int v = 0; v < 3; ++v) EXPECT_EQ(pictures[static_cast<std::size_t>(v)], cv::Size(200, 200));
  // Twice as wide, with the 320x240 camera's aspect ratio.
  EXPECT_EQ(pictures[3], cv::Size(400, 300));
}

}  // namespace
}  // namespace dispmvs::eval
