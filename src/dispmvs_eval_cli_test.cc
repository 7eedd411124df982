// dispmvs_eval end to end: a tiny workspace (one PINHOLE camera, two images,
// GT depth maps, predictions of known error), the printed table, the JSON
// file, the PNGs, and the error paths (one "error: " line, exit status 1).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model_io.h"
#include "eval/cloud_metrics.h"
#include "model/json.h"
#include "tests/support/model_builder.h"
#include "tests/support/run_program.h"
#include "tests/support/temp_dir.h"

#ifndef DISPMVS_EVAL_PROGRAM
#error "DISPMVS_EVAL_PROGRAM must name the dispmvs_eval binary"
#endif

namespace dispmvs::eval {
namespace {

namespace fs = std::filesystem;
using colmap_io::DenseArray;
using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::TempDir;
using dispmvs::testing::WriteFileBytes;

using dispmvs::testing::ExpectError;
using RunResult = dispmvs::testing::ProgramRun;

RunResult RunEval(const TempDir& dir, const std::string& args) {
  return dispmvs::testing::RunProgram(dir, DISPMVS_EVAL_PROGRAM, args);
}

using model::json::Value;

// The JSON file at `path`, parsed (malformed JSON throws: the test fails).
Value ReadJson(const fs::path& path) { return model::json::Parse(ReadFileBytes(path)); }

// Member `key` of the object `value`; a test failure and null when absent.
const Value& Member(const Value& value, const std::string& key) {
  static const Value kAbsent;
  const Value* member = value.Find(key);
  if (member == nullptr) {
    ADD_FAILURE() << "no member \"" << key << "\"";
    return kAbsent;
  }
  return *member;
}

// The number `value` holds; a test failure and NaN when it holds another type.
double Number(const Value& value) {
  if (value.type != Value::Type::kNumber) {
    ADD_FAILURE() << "not a number";
    return std::nan("");
  }
  return std::strtod(value.text.c_str(), nullptr);
}

double NumberAt(const Value& object, const std::string& key) { return Number(Member(object, key)); }

bool IsNull(const Value& value) { return value.type == Value::Type::kNull; }

// The element of the array `list` whose member `key` is the string `name`.
const Value& Entry(const Value& list, const std::string& key, const std::string& name) {
  static const Value kAbsent;
  for (const Value& element : list.array) {
    const Value* member = element.Find(key);
    if (member != nullptr && member->type == Value::Type::kString && member->text == name) {
      return element;
    }
  }
  ADD_FAILURE() << "no element with \"" << key << "\": \"" << name << "\"";
  return kAbsent;
}

// The entry of depth-map type `type`, and its view of `image`.
const Value& TypeEntry(const Value& report, const std::string& type) {
  return Entry(Member(report, "depth"), "type", type);
}
const Value& ViewEntry(const Value& report, const std::string& type, const std::string& image) {
  return Entry(Member(TypeEntry(report, type), "per_view"), "image", image);
}

// Whitespace-separated cells of a table line.
std::vector<std::string> Cells(const std::string& line) {
  std::vector<std::string> cells;
  std::istringstream in(line);
  for (std::string cell; in >> cell;) cells.push_back(cell);
  return cells;
}

std::vector<std::string> Fields(const std::string& line) {
  std::vector<std::string> fields;
  std::size_t begin = 0;
  for (;;) {
    const std::size_t tab = line.find('\t', begin);
    fields.push_back(line.substr(begin, tab - begin));
    if (tab == std::string::npos) return fields;
    begin = tab + 1;
  }
}

// Expects `actual` within a relative 1e-9 of `expected` (the JSON has 10
// significant digits).
void ExpectClose(double actual, double expected, const std::string& what) {
  EXPECT_NEAR(actual, expected, 1e-9 * std::max(1.0, std::abs(expected))) << what;
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// `text` with each line's cells joined by one space: tables compared by
// content, not by column width.
std::string Squeezed(const std::string& text) {
  std::string out;
  for (const std::string& line : Lines(text)) {
    std::string joined;
    for (const std::string& cell : Cells(line)) joined += (joined.empty() ? "" : " ") + cell;
    out += joined + "\n";
  }
  return out;
}

class EvalCliTest : public ::testing::Test {
 protected:
  static constexpr int kWidth = 8, kHeight = 6;

  void SetUp() override {
    ws_ = dir_.path() / "ws";
    dispmvs::testing::ModelBuilder builder;
    const auto camera = builder.AddPinholeCamera(kWidth, kHeight, 8, 8, 4, 3);
    const auto a = builder.AddImageWithPose(camera, "a.png", Eigen::Matrix3d::Identity(),
                                            Eigen::Vector3d::Zero());
    // b's centre (1, 0.25, 0) is off a's x-axis: not a rectified pair, so the
    // table has no disparity columns (RectifiedPairAddsDisparityColumns has them).
    const auto b = builder.AddImageWithPose(camera, "b.png", Eigen::Matrix3d::Identity(),
                                            Eigen::Vector3d(-1, -0.25, 0));
    builder.AddPoint({0.5, 0, 3}, {a, b});
    model_ = builder.model();
    colmap_io::WriteSparseModelBinary(model_, ws_ / "sparse");
    fs::create_directories(ws_ / "images");

    // GT, all pixels valid (48 per image, 96 in all).
    for (const char* name : {"a.png", "b.png"}) {
      DenseArray gt(kWidth, kHeight, 1);
      for (int r = 0; r < kHeight; ++r) {
        for (int c = 0; c < kWidth; ++c) {
          gt.at(r, c) = name[0] == 'a' ? 2.0f + 0.1f * r + 0.05f * c : 3.0f + 0.05f * r;
        }
      }
      colmap_io::WriteDenseArray(gt, ws_ / "ground_truth" / "depth_maps" / (std::string(name) + ".bin"));
      gt_[name] = gt;
      // dispmvs.geometric: GT * 1.015 on the left half, nothing on the right.
      DenseArray pred(kWidth, kHeight, 1, 0.0f);
      for (int r = 0; r < kHeight; ++r) {
        for (int c = 0; c < kWidth / 2; ++c) pred.at(r, c) = gt.at(r, c) * 1.015f;
      }
      WriteMap(name, "dispmvs.geometric", pred);
      // half: a 4x3 map (max_image_size 4) equal to the GT at (2 col, 2 row).
      DenseArray half(kWidth / 2, kHeight / 2, 1);
      for (int r = 0; r < kHeight / 2; ++r) {
        for (int c = 0; c < kWidth / 2; ++c) half.at(r, c) = gt.at(2 * r, 2 * c);
      }
      WriteMap(name, "half", half);
    }
    // geometric: exact, for a.png only.
    WriteMap("a.png", "geometric", gt_["a.png"]);
    // Maps of an image the model does not know are ignored.
    WriteMap("zz.png", "other", gt_["a.png"]);
  }

  void WriteMap(const std::string& name, const std::string& type, const DenseArray& map) {
    colmap_io::WriteDenseArray(map, ws_ / "stereo" / "depth_maps" / (name + "." + type + ".bin"));
  }

  std::string Ws() const { return "--workspace_path '" + ws_.string() + "'"; }

  TempDir dir_;
  fs::path ws_;
  colmap_io::SparseModel model_;
  std::map<std::string, DenseArray> gt_;
};

TEST_F(EvalCliTest, DepthTablePerViewJsonAndPngs) {
  const fs::path json = dir_.path() / "out" / "eval.json";
  const fs::path png = dir_.path() / "png";
  const RunResult run = RunEval(dir_, Ws() + " --per_view --json '" + json.string() +
                                          "' --png_dir '" + png.string() + "'");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  EXPECT_EQ(run.err, "");
  const std::string expected =
      "workspace: " + ws_.string() + "\n"
      "depth maps vs ground truth: 2 of 2 images have ground truth\n"
      "(pred: of the GT pixels with a prediction; all: of all GT pixels)\n"
      "type               views  coverage  abs_rel  med_rel  <1%pred  <2%pred  <5%pred   <1%all   <2%all   <5%all\n"
      "dispmvs.geometric    2/2    50.00%   0.0150   0.0150    0.00%  100.00%  100.00%    0.00%   50.00%   50.00%\n"
      "  a.png                     50.00%   0.0150   0.0150    0.00%  100.00%  100.00%    0.00%   50.00%   50.00%\n"
      "  b.png                     50.00%   0.0150   0.0150    0.00%  100.00%  100.00%    0.00%   50.00%   50.00%\n"
      "geometric            1/2   100.00%   0.0000   0.0000  100.00%  100.00%  100.00%  100.00%  100.00%  100.00%\n"
      "  a.png                    100.00%   0.0000   0.0000  100.00%  100.00%  100.00%  100.00%  100.00%  100.00%\n"
      "half                 2/2   100.00%   0.0000   0.0000  100.00%  100.00%  100.00%  100.00%  100.00%  100.00%\n"
      "  a.png                    100.00%   0.0000   0.0000  100.00%  100.00%  100.00%  100.00%  100.00%  100.00%\n"
      "  b.png                    100.00%   0.0000   0.0000  100.00%  100.00%  100.00%  100.00%  100.00%  100.00%\n"
      "png: 12 file(s) in " + png.string() + "\n"
      "json: " + json.string() + "\n";
  EXPECT_EQ(Squeezed(run.out), Squeezed(expected));

  // JSON: same numbers, unrounded; types in table order.
  const Value report = ReadJson(json);
  const Value& types = Member(report, "depth");
  ASSERT_EQ(types.array.size(), 3u);
  EXPECT_EQ(Member(types.array[0], "type").text, "dispmvs.geometric");
  EXPECT_EQ(Member(types.array[1], "type").text, "geometric");
  EXPECT_EQ(Member(types.array[2], "type").text, "half");
  EXPECT_TRUE(IsNull(Member(report, "gt_cloud")));
  EXPECT_EQ(NumberAt(report, "num_images"), 2);
  EXPECT_EQ(NumberAt(report, "views_with_gt"), 2);
  const Value& geometric = TypeEntry(report, "dispmvs.geometric");
  EXPECT_EQ(NumberAt(geometric, "views"), 2);
  const Value& overall = Member(geometric, "overall");
  EXPECT_EQ(NumberAt(overall, "gt_pixels"), 96);
  EXPECT_EQ(NumberAt(overall, "predicted_pixels"), 48);
  EXPECT_EQ(NumberAt(overall, "coverage"), 0.5);
  EXPECT_NEAR(NumberAt(overall, "abs_rel"), 0.015, 1e-6);
  EXPECT_NEAR(NumberAt(overall, "median_rel"), 0.015, 1e-6);
  EXPECT_EQ(NumberAt(overall, "within_1_of_predicted"), 0);
  EXPECT_EQ(NumberAt(overall, "within_2_of_predicted"), 1);
  EXPECT_EQ(NumberAt(overall, "within_5_of_predicted"), 1);
  EXPECT_EQ(NumberAt(overall, "within_1_of_gt"), 0);
  EXPECT_EQ(NumberAt(overall, "within_2_of_gt"), 0.5);
  EXPECT_EQ(NumberAt(overall, "within_5_of_gt"), 0.5);
  EXPECT_EQ(NumberAt(ViewEntry(report, "dispmvs.geometric", "a.png"), "gt_pixels"), 48);
  // The half-size maps: their size and the GT's, and the GT pixels they cover.
  const Value& half_a = ViewEntry(report, "half", "a.png");
  EXPECT_EQ(NumberAt(half_a, "width"), 4);
  EXPECT_EQ(NumberAt(half_a, "gt_width"), 8);
  EXPECT_EQ(NumberAt(half_a, "gt_pixels"), 12);  // the 4x3 map's pixels, at GT positions
  EXPECT_EQ(NumberAt(Member(TypeEntry(report, "half"), "overall"), "gt_pixels"), 24);  // 2 x 4x3

  // PNGs: GT per image, depth + error per map; the colour scale is the GT's.
  const cv::Mat gt_png = cv::imread((png / "a.png.gt.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(gt_png.empty());
  EXPECT_EQ(gt_png.size(), cv::Size(kWidth, kHeight));
  EXPECT_EQ(gt_png.type(), CV_8UC3);
  const cv::Mat half_png = cv::imread((png / "b.png.half.depth.png").string());
  EXPECT_EQ(half_png.size(), cv::Size(kWidth / 2, kHeight / 2));
  const cv::Mat exact = cv::imread((png / "a.png.geometric.depth.png").string());
  ASSERT_FALSE(exact.empty());
  EXPECT_EQ(cv::norm(exact, gt_png, cv::NORM_INF), 0.0);  // same scale, same depths
  const cv::Mat error = cv::imread((png / "a.png.dispmvs.geometric.error.png").string());
  ASSERT_FALSE(error.empty());
  EXPECT_EQ(error.at<cv::Vec3b>(0, kWidth - 1), cv::Vec3b(255, 255, 255));  // no prediction
  const cv::Vec3b left = error.at<cv::Vec3b>(0, 0);
  EXPECT_NE(left, cv::Vec3b(255, 255, 255));
  EXPECT_NE(left, cv::Vec3b(0, 0, 0));
  EXPECT_FALSE(fs::exists(png / "b.png.geometric.depth.png"));
  for (const auto& entry : fs::recursive_directory_iterator(png)) {
    EXPECT_EQ(entry.path().string().find(".tmp-"), std::string::npos) << entry.path();
  }
}

TEST_F(EvalCliTest, ChosenTypesAndPointClouds) {
  // GT cloud and a reconstruction with hand-computed distances.
  const std::vector<Eigen::Vector3f> gt = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const std::vector<Eigen::Vector3f> recon = {{0, 0, 0}, {1, 0, 0}, {0.5f, 0.5f, 0.5f}};
  const auto to_ply = [](const std::vector<Eigen::Vector3f>& points) {
    std::vector<colmap_io::PlyPoint> ply(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) {
      ply[i].xyz = {points[i].x(), points[i].y(), points[i].z()};
    }
    return ply;
  };
  colmap_io::WritePlyPoints(to_ply(gt), ws_ / "ground_truth" / "points.ply");
  colmap_io::WritePlyPoints(to_ply(recon), ws_ / "fused.ply");
  const std::string fused = (ws_ / "fused.ply").string();

  // Defaults: tau = 0.2 % and cut-off = 2 % of the diagonal sqrt(3).
  // recon -> GT: 0, 0, sqrt(0.75) (cut); GT -> recon: 0, 0, sqrt(0.75) x 2 (cut).
  RunResult run = RunEval(dir_, Ws() + " --types dispmvs.geometric,photometric --ply '" + fused +
                                    "' --json '" + (dir_.path() / "c.json").string() + "'");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  std::vector<std::string> lines = Lines(run.out);
  ASSERT_EQ(lines.size(), 12u) << run.out;
  EXPECT_EQ(Cells(lines[4]).at(0), "dispmvs.geometric");
  EXPECT_EQ(Cells(lines[4]).at(1), "2/2");
  EXPECT_EQ(Cells(lines[4]).at(2), "50.00%");
  EXPECT_EQ(Cells(lines[5]), (std::vector<std::string>{"photometric", "no", "maps"}));
  EXPECT_EQ(lines[6], "");
  EXPECT_EQ(lines[7], "point clouds vs ground truth: GT " +
                          (ws_ / "ground_truth" / "points.ply").string() +
                          ", 4 points, bounding-box diagonal 1.7321");
  EXPECT_EQ(lines[8],
            "(distances in scene units; tau 0.0034641 (0.2% of the diagonal), outlier cut-off "
            "0.034641 (2% of the diagonal))");
  EXPECT_EQ(Cells(lines[9]), Cells("ply points accuracy completeness overall acc_cut comp_cut "
                                   "precision recall F-score"));
  EXPECT_EQ(Cells(lines[10]), Cells(fused + " 3 0 0 0 1 2 66.67% 50.00% 57.14%"));
  const Value json = ReadJson(dir_.path() / "c.json");
  EXPECT_NEAR(NumberAt(Member(json, "gt_cloud"), "bbox_diagonal"), std::sqrt(3.0), 1e-9);
  ASSERT_EQ(Member(json, "clouds").array.size(), 1u);
  const Value& cloud = Member(json, "clouds").array[0];
  EXPECT_NEAR(NumberAt(cloud, "fscore"), 4.0 / 7.0, 1e-9);
  EXPECT_EQ(NumberAt(cloud, "accuracy_cut"), 1);
  EXPECT_EQ(NumberAt(cloud, "completeness_cut"), 2);
  EXPECT_EQ(NumberAt(TypeEntry(json, "photometric"), "views"), 0);
  EXPECT_TRUE(IsNull(Member(TypeEntry(json, "photometric"), "overall")));

  // Thresholds in scene units: nothing cut.
  run = RunEval(dir_, Ws() + " --types half --ply '" + fused + "' --tau 0.9 --cutoff 1");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  lines = Lines(run.out);
  ASSERT_EQ(lines.size(), 10u) << run.out;
  EXPECT_EQ(lines[7], "(distances in scene units; tau 0.9, outlier cut-off 1)");
  // accuracy sqrt(0.75) / 3 = 0.28868, completeness 2 sqrt(0.75) / 4 = 0.43301.
  EXPECT_EQ(Cells(lines[9]), Cells(fused + " 3 0.28868 0.43301 0.36084 0 0 100.00% 100.00% 100.00%"));
}

TEST_F(EvalCliTest, GroundTruthCloudFromDepthMaps) {
  // Without ground_truth/points.ply the GT cloud is the GT maps back-projected;
  // a reconstruction made the same way matches it exactly.
  std::vector<colmap_io::PlyPoint> ply;
  for (const auto& [id, image] : model_.images) {
    PointCloud points;
    BackProjectDepthMap(gt_[image.name], model_.cameras.at(image.camera_id), image, 1, &points);
    for (const Eigen::Vector3f& p : points) {
      colmap_io::PlyPoint point;
      point.xyz = {p.x(), p.y(), p.z()};
      ply.push_back(point);
    }
  }
  ASSERT_EQ(ply.size(), 96u);
  const fs::path fused = dir_.path() / "from_maps.ply";
  colmap_io::WritePlyPoints(ply, fused);
  const RunResult run = RunEval(dir_, Ws() + " --ply '" + fused.string() + "'");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  EXPECT_NE(run.out.find("GT ground-truth depth maps (stride 1), 96 points"), std::string::npos)
      << run.out;
  const std::vector<std::string> lines = Lines(run.out);
  const auto row = std::find_if(lines.begin(), lines.end(), [&](const std::string& line) {
    return line.rfind(fused.string() + " ", 0) == 0;
  });
  ASSERT_NE(row, lines.end()) << run.out;
  EXPECT_EQ(Cells(*row), Cells(fused.string() + " 96 0 0 0 0 0 100.00% 100.00% 100.00%"));
  // Stride 2: a quarter of the GT points, all still matched by the reconstruction.
  const RunResult strided = RunEval(dir_, Ws() + " --gt_stride 2 --ply '" + fused.string() + "'");
  ASSERT_EQ(strided.status, 0) << strided.out << strided.err;
  EXPECT_NE(strided.out.find("(stride 2), 24 points"), std::string::npos) << strided.out;
}

TEST_F(EvalCliTest, MapsOfImagesWithoutGroundTruthAreNotScored) {
  colmap_io::Image c = model_.images.at(1);
  c.image_id = 3;
  c.name = "c.png";
  c.points2D.clear();
  model_.images[3] = c;
  colmap_io::WriteSparseModelBinary(model_, ws_ / "sparse");
  WriteMap("c.png", "dispmvs.geometric", DenseArray(kWidth, kHeight, 1, 1.0f));
  WriteMap("c.png", "only_c", DenseArray(kWidth, kHeight, 1, 1.0f));
  const RunResult run = RunEval(dir_, Ws() + " --types dispmvs.geometric,only_c");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  const std::vector<std::string> lines = Lines(run.out);
  ASSERT_EQ(lines.size(), 8u) << run.out;
  EXPECT_EQ(lines[1], "depth maps vs ground truth: 2 of 3 images have ground truth");
  EXPECT_EQ(Cells(lines[4]).at(0), "dispmvs.geometric");
  EXPECT_EQ(Cells(lines[4]).at(1), "2/2");
  EXPECT_EQ(Cells(lines[4]).at(2), "50.00%");
  EXPECT_EQ(Cells(lines[5]),
            Cells("only_c no maps for images with ground truth"));
  EXPECT_EQ(lines[6], "note: dispmvs.geometric: 1 map(s) of images without ground truth, not scored");
  EXPECT_EQ(lines[7], "note: only_c: 1 map(s) of images without ground truth, not scored");
  // Only maps of images without ground truth: nothing to score.
  ExpectError(RunEval(dir_, Ws() + " --types only_c"), "no depth map of type(s) only_c");
}

TEST_F(EvalCliTest, RectifiedPairAddsDisparityColumns) {
  // a and b: a rectified pair (identity rotations, centres 1 apart along x,
  // one camera: f = 8, so disparity = 8 / z); c is 1 below a: no partner.
  dispmvs::testing::ModelBuilder builder;
  const auto camera = builder.AddPinholeCamera(kWidth, kHeight, 8, 8, 4, 3);
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const auto a = builder.AddImageWithPose(camera, "a.png", I, Eigen::Vector3d::Zero());
  const auto b = builder.AddImageWithPose(camera, "b.png", I, Eigen::Vector3d(-1, 0, 0));
  const auto c = builder.AddImageWithPose(camera, "c.png", I, Eigen::Vector3d(0, -1, 0));
  builder.AddPoint({0.5, 0, 3}, {a, b, c});
  colmap_io::WriteSparseModelBinary(builder.model(), ws_ / "sparse");
  gt_["c.png"] = DenseArray(kWidth, kHeight, 1, 3.0f);
  colmap_io::WriteDenseArray(gt_["c.png"], ws_ / "ground_truth" / "depth_maps" / "c.png.bin");

  // "stereo": a's disparity off by 0.5, 1.5 and 3 px in column pairs 0-1,
  // 2-3, 4-5, nothing in 6-7; b and c exact.
  const auto shifted = [](float depth, double shift) {
    return static_cast<float>(8.0 / (8.0 / depth + shift));
  };
  const DenseArray& gt_a = gt_["a.png"];
  DenseArray stereo_a(kWidth, kHeight, 1, 0.0f);
  const double shifts[] = {0.5, 1.5, 3.0};
  for (int r = 0; r < kHeight; ++r) {
    for (int col = 0; col < 6; ++col) stereo_a.at(r, col) = shifted(gt_a.at(r, col), shifts[col / 2]);
  }
  WriteMap("a.png", "stereo", stereo_a);
  WriteMap("b.png", "stereo", gt_["b.png"]);
  WriteMap("c.png", "stereo", gt_["c.png"]);
  // "half" (4x3 maps): a's off by 1.5 px at the GT's resolution (0.75 px of
  // the map's own), b's exact (from the fixture).
  DenseArray half_a(kWidth / 2, kHeight / 2, 1);
  for (int r = 0; r < kHeight / 2; ++r) {
    for (int col = 0; col < kWidth / 2; ++col) half_a.at(r, col) = shifted(gt_a.at(2 * r, 2 * col), 1.5);
  }
  WriteMap("a.png", "half", half_a);

  const fs::path json = dir_.path() / "r.json";
  const fs::path tsv = dir_.path() / "r.tsv";
  const RunResult run = RunEval(dir_, Ws() + " --types stereo,half,photometric --per_view --json '" +
                                          json.string() + "' --tsv '" + tsv.string() + "'");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  const std::vector<std::string> lines = Lines(run.out);
  ASSERT_EQ(lines.size(), 15u) << run.out;
  EXPECT_EQ(lines[1], "depth maps vs ground truth: 3 of 3 images have ground truth");
  EXPECT_EQ(lines[3],
            "(disparity, over the 2 view(s) with a rectified partner: disp_err = mean "
            "|f B / d - f B / gt| in GT pixels; <Npx: error < N px)");
  const std::vector<std::string> header = Cells(lines[4]);
  ASSERT_EQ(header.size(), 16u) << lines[4];
  EXPECT_EQ(std::vector<std::string>(header.begin() + 11, header.end()),
            (std::vector<std::string>{"disp_err", "<1pxpred", "<2pxpred", "<1pxall", "<2pxall"}));
  const auto disparity_cells = [&](int line) {
    const std::vector<std::string> cells = Cells(lines[line]);
    if (cells.size() < 5) return cells;
    return std::vector<std::string>(cells.end() - 5, cells.end());
  };
  using Strings = std::vector<std::string>;
  // stereo over a and b: 96 GT pixels, 84 predicted; errors 0.5 (12 px),
  // 1.5 (12), 3 (12) and 0 (48): mean 60 / 84, < 1 px 60, < 2 px 72.
  EXPECT_EQ(Cells(lines[5])[0], "stereo");
  EXPECT_EQ(Cells(lines[5])[1], "3/3");
  EXPECT_EQ(disparity_cells(5), (Strings{"0.714", "71.43%", "85.71%", "62.50%", "75.00%"}));
  EXPECT_EQ(disparity_cells(6), (Strings{"1.667", "33.33%", "66.67%", "25.00%", "50.00%"}));
  EXPECT_EQ(disparity_cells(7), (Strings{"0.000", "100.00%", "100.00%", "100.00%", "100.00%"}));
  EXPECT_EQ(Cells(lines[8])[0], "c.png");
  EXPECT_EQ(disparity_cells(8), (Strings{"n/a", "n/a", "n/a", "n/a", "n/a"}));
  // half: errors in GT pixels, 1.5 for a's 12 pixels, 0 for b's.
  EXPECT_EQ(Cells(lines[9])[1], "2/3");
  EXPECT_EQ(disparity_cells(9), (Strings{"0.750", "50.00%", "100.00%", "50.00%", "100.00%"}));
  EXPECT_EQ(disparity_cells(10), (Strings{"1.500", "0.00%", "100.00%", "0.00%", "100.00%"}));
  EXPECT_EQ(Cells(lines[12]), (std::vector<std::string>{"photometric", "no", "maps"}));

  // JSON: the same, unrounded; null without a partner.
  const Value report = ReadJson(json);
  EXPECT_EQ(NumberAt(report, "views_with_rectified_partner"), 2);
  const Value& stereo = TypeEntry(report, "stereo");
  EXPECT_EQ(NumberAt(stereo, "disparity_views"), 2);
  const Value& overall = Member(stereo, "overall");
  EXPECT_EQ(NumberAt(overall, "disparity_gt_pixels"), 96);
  EXPECT_EQ(NumberAt(overall, "disparity_predicted_pixels"), 84);
  EXPECT_NEAR(NumberAt(overall, "disparity_mean_error"), 60.0 / 84, 1e-6);
  EXPECT_NEAR(NumberAt(overall, "disparity_within_1px_of_predicted"), 60.0 / 84, 1e-9);
  EXPECT_NEAR(NumberAt(overall, "disparity_within_2px_of_gt"), 0.75, 1e-9);
  const Value& view_a = ViewEntry(report, "stereo", "a.png");
  EXPECT_EQ(Member(view_a, "rectified_partner").text, "b.png");
  EXPECT_NEAR(NumberAt(view_a, "baseline"), 1.0, 1e-12);
  EXPECT_EQ(NumberAt(view_a, "disparity_focal"), 8);
  EXPECT_NEAR(NumberAt(view_a, "disparity_mean_error"), 5.0 / 3, 1e-6);
  const Value& view_c = ViewEntry(report, "stereo", "c.png");
  EXPECT_TRUE(IsNull(Member(view_c, "rectified_partner")));
  EXPECT_TRUE(IsNull(Member(view_c, "disparity_gt_pixels")));
  EXPECT_TRUE(IsNull(Member(view_c, "disparity_within_2px_of_gt")));

  // TSV: the sums; the disparity counts cover a and b only.
  const std::vector<std::string> tsv_lines = Lines(ReadFileBytes(tsv));
  std::vector<std::vector<std::string>> depth;
  for (const std::string& line : tsv_lines) {
    if (line.rfind("depth\t", 0) == 0) depth.push_back(Fields(line));
  }
  ASSERT_EQ(depth.size(), 3u);
  EXPECT_EQ(depth[0][1], "stereo");
  EXPECT_EQ(depth[0][2], "3");
  EXPECT_EQ(depth[0][3], "144");
  EXPECT_EQ(depth[0][4], "132");
  EXPECT_EQ(std::vector<std::string>(depth[0].begin() + 9, depth[0].end()),
            (Strings{"96", "60", "72"}));
  EXPECT_EQ(std::vector<std::string>(depth[1].begin() + 9, depth[1].end()),
            (Strings{"24", "12", "24"}));
  EXPECT_EQ(depth[2], (Strings{"depth", "photometric", "0", "0", "0", "0", "0", "0", "0", "0",
                               "0", "0"}));
}

TEST_F(EvalCliTest, TsvAgreesWithJson) {
  const std::vector<colmap_io::PlyPoint> gt = {{{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 0}}, {{0, 0, 1}}};
  const std::vector<colmap_io::PlyPoint> recon = {{{0, 0, 0}}, {{1, 0, 0}}, {{0.5f, 0.5f, 0.5f}}};
  colmap_io::WritePlyPoints(gt, ws_ / "ground_truth" / "points.ply");
  colmap_io::WritePlyPoints(recon, ws_ / "fused.ply");
  const std::string fused = (ws_ / "fused.ply").string();
  const fs::path json = dir_.path() / "s.json";
  const fs::path tsv = dir_.path() / "deep" / "s.tsv";
  const RunResult run = RunEval(dir_, Ws() + " --ply '" + fused + "' --json '" + json.string() +
                                          "' --tsv '" + tsv.string() + "'");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  EXPECT_NE(run.out.find("\ntsv: " + tsv.string() + "\n"), std::string::npos) << run.out;
  for (const auto& entry : fs::directory_iterator(tsv.parent_path())) {
    EXPECT_EQ(entry.path().filename(), "s.tsv");  // no temporary left behind
  }
  const Value report = ReadJson(json);
  const std::string table = ReadFileBytes(tsv);
  ASSERT_FALSE(table.empty());
  EXPECT_EQ(table.back(), '\n');

  int depth_headers = 0, cloud_headers = 0, depth_rows = 0, cloud_rows = 0;
  for (const std::string& line : Lines(table)) {
    ASSERT_FALSE(line.empty());
    const std::vector<std::string> f = Fields(line);
    if (line[0] == '#') {
      if (f[0] == "#depth") {
        ++depth_headers;
        EXPECT_EQ(line, "#depth\ttype\tviews\tgt_pixels\tpredicted\twithin_1\twithin_2\t"
                        "within_5\tabs_rel_sum\tdisparity_gt_pixels\tdisparity_within_1px\t"
                        "disparity_within_2px");
        EXPECT_EQ(depth_rows, 0);  // before the rows
      } else if (f[0] == "#cloud") {
        ++cloud_headers;
        EXPECT_EQ(line, "#cloud\tply\tpoints\tgt_points\taccuracy\tcompleteness\toverall\t"
                        "precision\trecall\tfscore\ttau\tcutoff");
        EXPECT_EQ(cloud_rows, 0);
      }
      continue;
    }
    if (f[0] == "depth") {
      ++depth_rows;
      ASSERT_EQ(f.size(), 12u) << line;
      const Value& type = TypeEntry(report, f[1]);
      const Value& at = Member(type, "overall");
      EXPECT_EQ(std::stod(f[2]), NumberAt(type, "views")) << line;
      const double gt_pixels = std::stod(f[3]);
      const double predicted = std::stod(f[4]);
      EXPECT_EQ(gt_pixels, NumberAt(at, "gt_pixels")) << line;
      EXPECT_EQ(predicted, NumberAt(at, "predicted_pixels")) << line;
      ExpectClose(predicted / gt_pixels, NumberAt(at, "coverage"), line);
      ExpectClose(std::stod(f[5]) / gt_pixels, NumberAt(at, "within_1_of_gt"), line);
      ExpectClose(std::stod(f[6]) / gt_pixels, NumberAt(at, "within_2_of_gt"), line);
      ExpectClose(std::stod(f[7]) / gt_pixels, NumberAt(at, "within_5_of_gt"), line);
      ExpectClose(std::stod(f[6]) / predicted, NumberAt(at, "within_2_of_predicted"),
                  line);
      ExpectClose(std::stod(f[8]) / predicted, NumberAt(at, "abs_rel"), line);
      // No rectified pair in this workspace.
      EXPECT_EQ(std::vector<std::string>(f.begin() + 9, f.end()),
                (std::vector<std::string>{"0", "0", "0"}));
    } else if (f[0] == "cloud") {
      ++cloud_rows;
      ASSERT_EQ(f.size(), 12u) << line;
      EXPECT_EQ(f[1], fused);
      ASSERT_EQ(Member(report, "clouds").array.size(), 1u);
      const Value& at = Member(report, "clouds").array[0];
      EXPECT_EQ(f[2], "3");
      EXPECT_EQ(f[3], "4");
      const char* keys[] = {"accuracy", "completeness", "overall", "precision",
                            "recall",   "fscore",       "tau",     "cutoff"};
      for (int i = 0; i < 8; ++i) {
        ExpectClose(std::stod(f[4 + i]), NumberAt(at, keys[i]), keys[i]);
      }
      ExpectClose(std::stod(f[9]), 4.0 / 7.0, "fscore");
    } else {
      ADD_FAILURE() << "unexpected line: " << line;
    }
  }
  EXPECT_EQ(depth_headers, 1);
  EXPECT_EQ(cloud_headers, 1);
  EXPECT_EQ(depth_rows, 3);  // dispmvs.geometric, geometric, half
  EXPECT_EQ(cloud_rows, 1);
  // Exact sums: dispmvs.geometric's abs_rel_sum is 48 pixels of rel. error
  // 0.015 (float rounding aside), printed with 17 digits.
  const std::size_t row = table.find("depth\tdispmvs.geometric\t2\t96\t48\t0\t48\t48\t");
  ASSERT_NE(row, std::string::npos) << table;
  const std::string abs_rel_sum = Fields(table.substr(row, table.find('\n', row) - row))[8];
  EXPECT_NEAR(std::stod(abs_rel_sum), 48 * 0.015, 1e-5);
  EXPECT_GE(abs_rel_sum.size(), 15u) << abs_rel_sum;
}

// --regions: every GT pixel in exactly one visibility class, the seen ones
// in exactly one edge ring, and the classes' counts add up to the depth
// record's (b sees a's right part; a sees b's left part).
TEST_F(EvalCliTest, RegionsSplitEveryGroundTruthPixelOnce) {
  const fs::path tsv = dir_.path() / "regions.tsv";
  const RunResult run = RunEval(dir_, Ws() + " --types dispmvs.geometric --regions --tsv '" + tsv.string() + "'");
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  EXPECT_NE(run.out.find("error regions: the GT pixels by whether another view"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("seen, 13+ px from a depth edge"), std::string::npos) << run.out;
  int64_t depth_gt = -1, depth_within_2 = -1, visibility_gt = 0, visibility_within_2 = 0, seen_gt = -1, rings_gt = 0;
  int region_rows = 0;
  for (const std::string& line : Lines(ReadFileBytes(tsv))) {
    const std::vector<std::string> f = Fields(line);
    if (f[0] == "depth") {
      depth_gt = std::stoll(f[3]);
      depth_within_2 = std::stoll(f[6]);
    } else if (f[0] == "region") {
      ASSERT_EQ(f.size(), 7u) << line;
      EXPECT_EQ(f[1], "dispmvs.geometric");
      ++region_rows;
      const int64_t gt = std::stoll(f[3]);
      EXPECT_GE(gt, std::stoll(f[5]));
      if (f[2].rfind("seen, ", 0) == 0) {
        rings_gt += gt;
      } else {
        visibility_gt += gt;
        visibility_within_2 += std::stoll(f[5]);
        if (f[2] == "seen by another view") seen_gt = gt;
      }
    }
  }
  EXPECT_EQ(region_rows, 8);
  EXPECT_EQ(depth_gt, 96);
  EXPECT_EQ(visibility_gt, depth_gt);
  EXPECT_EQ(visibility_within_2, depth_within_2);
  EXPECT_GT(seen_gt, 0);
  EXPECT_LT(seen_gt, depth_gt);  // each view's far side lies outside the other
  EXPECT_EQ(rings_gt, seen_gt);

  ExpectError(RunEval(dir_, Ws() + " --compare dispmvs.geometric,geometric --regions"),
              "--regions scores against ground truth; --compare does not use it");
}

TEST_F(EvalCliTest, HelpAndErrors) {
  RunResult run = RunEval(dir_, "--help");
  EXPECT_EQ(run.status, 0);
  EXPECT_NE(run.out.find("Usage: dispmvs_eval --workspace_path WS"), std::string::npos);
  EXPECT_NE(run.out.find("--png_dir"), std::string::npos);
  EXPECT_NE(run.out.find("--tsv FILE writes a summary"), std::string::npos);
  EXPECT_NE(run.out.find("depth TYPE views gt_pixels predicted within_1 within_2 within_5 "
                         "abs_rel_sum"),
            std::string::npos);
  EXPECT_NE(run.out.find("cloud PLY points gt_points accuracy completeness overall precision "
                         "recall"),
            std::string::npos);

  ExpectError(RunEval(dir_, ""), "--workspace_path is required");
  ExpectError(RunEval(dir_, "--workspace_path '" + (dir_.path() / "nope").string() + "'"),
              "nope");
  ExpectError(RunEval(dir_, Ws() + " --bogus"), "bogus");
  ExpectError(RunEval(dir_, Ws() + " --types ,"), "--types");
  ExpectError(RunEval(dir_, Ws() + " --tau -1"), "--tau");
  ExpectError(RunEval(dir_, Ws() + " --types photometric,geometric.x"),
              "no depth map of type(s) photometric, geometric.x for any image with ground truth");
  ExpectError(RunEval(dir_, Ws() + " --ply '" + (dir_.path() / "missing.ply").string() + "'"),
              "missing.ply: no such file");
  ExpectError(RunEval(dir_, Ws() + " --tsv ''"), "--tsv needs a file name");
  ExpectError(RunEval(dir_, Ws() + " --ply 'a\tb.ply' --tsv x.tsv"),
              "contains a tab or a line break, which --tsv cannot hold");
  // A TSV path under a regular file cannot be written.
  WriteFileBytes(dir_.path() / "plain", "x");
  ExpectError(RunEval(dir_, Ws() + " --tsv '" + (dir_.path() / "plain" / "s.tsv").string() + "'"),
              "s.tsv");

  // A map whose size is not a clean scale of the GT.
  WriteMap("b.png", "bad", DenseArray(6, 3, 1, 1.0f));
  ExpectError(RunEval(dir_, Ws() + " --types bad"), "b.png.bad.bin: depth map is 6x3 but its "
                                                    "ground truth is 8x6");
  // A truncated map.
  WriteFileBytes(ws_ / "stereo" / "depth_maps" / "a.png.trunc.bin", "8&6&1&0123456789");
  ExpectError(RunEval(dir_, Ws() + " --types trunc"), "a.png.trunc.bin");
  // A GT map of the wrong size.
  colmap_io::WriteDenseArray(DenseArray(4, 4, 1, 1.0f),
                             ws_ / "ground_truth" / "depth_maps" / "b.png.bin");
  ExpectError(RunEval(dir_, Ws() + " --types geometric"),
              "b.png.bin: ground-truth depth map is 4x4 but its camera is 8x6");
  // No ground truth at all.
  fs::remove_all(ws_ / "ground_truth");
  ExpectError(RunEval(dir_, Ws()), "no ground truth");
  fs::create_directories(ws_ / "ground_truth" / "depth_maps");
  ExpectError(RunEval(dir_, Ws()), "no ground-truth depth map NAME.bin for any of the 2 images");
}

}  // namespace
}  // namespace dispmvs::eval
