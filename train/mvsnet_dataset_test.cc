#include "train/mvsnet_dataset.h"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#ifdef DISPMVS_HAVE_OPENCV
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#endif

#include "model/safetensors.h"
#include "tests/support/temp_dir.h"
#include "train/trainer.h"

namespace dispmvs::train {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;
using testing::WriteFileBytes;

// The message of the std::runtime_error that `f` throws ("<no error>" if it
// throws none; other exception types fail the test by escaping).
std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "<no error>";
}

#define EXPECT_CONTAINS(text, part) \
  EXPECT_NE(std::string(text).find(part), std::string::npos) << "'" << (text) << "' lacks '" << (part) << "'"

// A cam.txt in the layout of the MVSNet releases (blank lines included).
std::string CamText(const std::string& extrinsic_rows, const std::string& intrinsic_rows,
                    const std::string& depth_line) {
  return "extrinsic\n" + extrinsic_rows + "\nintrinsic\n" + intrinsic_rows + "\n" + depth_line + "\n";
}

const char* kRotZ =  // rotation about z with exactly representable-in-text entries
    "0.6 -0.8 0.0 1.5\n"
    "0.8 0.6 0.0 -2.25\n"
    "0.0 0.0 1.0 425.0\n"
    "0.0 0.0 0.0 1.0\n";
const char* kK =
    "361.54 0.0 82.9\n"
    "0.0 360.35 66.38\n"
    "0.0 0.0 1.0\n";

// ------------------------------------------------------------------ cam.txt

TEST(MvsnetCameraTest, ParsesMatricesAndDepthRangeExactly) {
  const MvsnetCamera cam = ParseMvsnetCamera(CamText(kRotZ, kK, "425.0 2.5"), "cam.txt");
  const std::array<double, 16> w2c{0.6, -0.8, 0.0, 1.5, 0.8, 0.6, 0.0, -2.25, 0.0, 0.0, 1.0, 425.0, 0, 0, 0, 1};
  const std::array<double, 9> k{361.54, 0.0, 82.9, 0.0, 360.35, 66.38, 0.0, 0.0, 1.0};
  EXPECT_EQ(cam.world_to_camera, w2c);
  EXPECT_EQ(cam.intrinsics, k);
  EXPECT_EQ(cam.depth_min, 425.0);
  EXPECT_EQ(cam.depth_interval, 2.5);
  EXPECT_EQ(cam.depth_num, 192);               // the default
  EXPECT_EQ(cam.depth_max, 425.0 + 2.5 * 191);  // 902.5

  const MvsnetCamera with_num = ParseMvsnetCamera(CamText(kRotZ, kK, "425.0 2.5 128.0"), "cam.txt");
  EXPECT_EQ(with_num.depth_num, 128);
  EXPECT_EQ(with_num.depth_max, 425.0 + 2.5 * 127);

  const MvsnetCamera with_max = ParseMvsnetCamera(CamText(kRotZ, kK, "425.0 2.5 192 935.25"), "cam.txt");
  EXPECT_EQ(with_max.depth_max, 935.25);  // given: wins over min + interval * (num - 1)
}

TEST(MvsnetCameraTest, ToleratesCrLfAndMissingBlankLines) {
  std::string text = "extrinsic\r\n";
  for (const char* row : {"1 0 0 0", "0 1 0 0", "0 0 1 0", "0 0 0 1"}) text += std::string(row) + "  \r\n";
  text += "intrinsic\r\n100 0 50\r\n0 100 40\r\n0 0 1\r\n2.0 0.5\r\n\r\n";
  const MvsnetCamera cam = ParseMvsnetCamera(text, "crlf_cam.txt");
  EXPECT_EQ(cam.intrinsics[2], 50.0);
  EXPECT_EQ(cam.depth_max, 2.0 + 0.5 * 191);
}

TEST(MvsnetCameraTest, MalformedFilesNameFileAndLine) {
  // Truncated: the file stops inside the intrinsic matrix.
  const std::string full = CamText(kRotZ, kK, "425.0 2.5");
  const std::string truncated = full.substr(0, full.find("0.0 0.0 1.0\n", full.find("intrinsic")));
  std::string e = ErrorOf([&] { ParseMvsnetCamera(truncated, "scan1/cams/00000003_cam.txt"); });
  EXPECT_CONTAINS(e, "scan1/cams/00000003_cam.txt");
  EXPECT_CONTAINS(e, "truncated");
  EXPECT_CONTAINS(e, "intrinsic row 3");

  e = ErrorOf([&] { ParseMvsnetCamera(CamText(kRotZ, kK, ""), "c.txt"); });
  EXPECT_CONTAINS(e, "truncated");

  // NaN in the second extrinsic row (line 3).
  std::string nan_rows = kRotZ;
  nan_rows.replace(nan_rows.find("-2.25"), 5, "nan");
  e = ErrorOf([&] { ParseMvsnetCamera(CamText(nan_rows, kK, "425.0 2.5"), "c.txt"); });
  EXPECT_CONTAINS(e, "c.txt:3:");
  EXPECT_CONTAINS(e, "finite");

  // The depth line is line 12 (extrinsic 1-5, blank, intrinsic 7-10, blank).
  e = ErrorOf([&] { ParseMvsnetCamera(CamText(kRotZ, kK, "0 2.5"), "c.txt"); });
  EXPECT_CONTAINS(e, "c.txt:12:");
  EXPECT_CONTAINS(e, "DEPTH_MIN must be > 0");
  e = ErrorOf([&] { ParseMvsnetCamera(CamText(kRotZ, kK, "-3 2.5"), "c.txt"); });
  EXPECT_CONTAINS(e, "DEPTH_MIN must be > 0");
  e = ErrorOf([&] { ParseMvsnetCamera(CamText(kRotZ, kK, "425 0"), "c.txt"); });
  EXPECT_CONTAINS(e, "DEPTH_INTERVAL must be > 0");
  e = ErrorOf([&] { ParseMvsnetCamera(CamText(kRotZ, kK, "425 2.5 192 400"), "c.txt"); });
  EXPECT_CONTAINS(e, "DEPTH_MAX must be > DEPTH_MIN");
  e = ErrorOf([&] { ParseMvsnetCamera(CamText(kRotZ, kK, "425 2.5 19.5"), "c.txt"); });
  EXPECT_CONTAINS(e, "DEPTH_NUM");

  // A row with three values (line 2).
  std::string short_row = kRotZ;
  short_row.replace(short_row.find(" 1.5"), 4, "");
  e = ErrorOf([&] { ParseMvsnetCamera(CamText(short_row, kK, "425.0 2.5"), "c.txt"); });
  EXPECT_CONTAINS(e, "c.txt:2:");
  EXPECT_CONTAINS(e, "found 3 values");

  e = ErrorOf([&] { ParseMvsnetCamera(CamText(kRotZ, kK, "425.0 2.5") + "1 2 3\n", "c.txt"); });
  EXPECT_CONTAINS(e, "c.txt:13:");
  EXPECT_CONTAINS(e, "unexpected content");

  // A projection-like matrix is not a rigid motion.
  e = ErrorOf([&] {
    ParseMvsnetCamera(CamText("2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n", kK, "425 2.5"), "c.txt");
  });
  EXPECT_CONTAINS(e, "orthonormal");
  e = ErrorOf([&] { ParseMvsnetCamera(CamText(kRotZ, "0 0 82.9\n0 360 66\n0 0 1\n", "425 2.5"), "c.txt"); });
  EXPECT_CONTAINS(e, "fx must be > 0");
  e = ErrorOf([&] { ParseMvsnetCamera("intrinsic\n", "c.txt"); });
  EXPECT_CONTAINS(e, "c.txt:1: expected 'extrinsic'");
}

// ------------------------------------------------------------------ pair.txt

TEST(MvsnetPairsTest, ParsesReferencesSourcesAndScores) {
  const auto pairs = ParseMvsnetPairs("3\n0\n2 1 10.5 2 3.25\n2\n1 0 7\n1\n0\n", "pair.txt");
  ASSERT_EQ(pairs.size(), 3u);
  EXPECT_EQ(pairs[0].reference, 0);
  EXPECT_EQ(pairs[0].sources, (std::vector<int64_t>{1, 2}));
  EXPECT_EQ(pairs[0].scores, (std::vector<double>{10.5, 3.25}));
  EXPECT_EQ(pairs[1].reference, 2);  // the file's order, not sorted
  EXPECT_EQ(pairs[1].sources, (std::vector<int64_t>{0}));
  EXPECT_EQ(pairs[2].reference, 1);
  EXPECT_TRUE(pairs[2].sources.empty());
}

TEST(MvsnetPairsTest, MalformedFilesNameFileAndLine) {
  std::string e = ErrorOf([] { ParseMvsnetPairs("3\n0\n2 1 10.5 5 3.25\n", "scan/pair.txt"); });
  EXPECT_CONTAINS(e, "scan/pair.txt:3:");
  EXPECT_CONTAINS(e, "view 5 out of range");

  e = ErrorOf([] { ParseMvsnetPairs("3\n0\n1 1 1\n1\n1 0 1\n", "pair.txt"); });
  EXPECT_CONTAINS(e, "truncated after line 5");
  EXPECT_CONTAINS(e, "entry 3 of 3");

  e = ErrorOf([] { ParseMvsnetPairs("2\n0\n1 1 1\n0\n1 1 1\n", "pair.txt"); });
  EXPECT_CONTAINS(e, "pair.txt:4:");
  EXPECT_CONTAINS(e, "listed twice");

  e = ErrorOf([] { ParseMvsnetPairs("3\n0\n2 1 1.0\n1\n1 0 1\n2\n1 0 1\n", "pair.txt"); });
  EXPECT_CONTAINS(e, "pair.txt:3:");
  EXPECT_CONTAINS(e, "source/score pairs");

  e = ErrorOf([] { ParseMvsnetPairs("2\n0\n1 0 1.0\n1\n1 0 1\n", "pair.txt"); });
  EXPECT_CONTAINS(e, "its own source");
  e = ErrorOf([] { ParseMvsnetPairs("2\n0\n1 1 nan\n1\n1 0 1\n", "pair.txt"); });
  EXPECT_CONTAINS(e, "finite");
  e = ErrorOf([] { ParseMvsnetPairs("2\n0\n1 1 1\n1\n1 0 1\n7\n", "pair.txt"); });
  EXPECT_CONTAINS(e, "pair.txt:6: unexpected content");
  e = ErrorOf([] { ParseMvsnetPairs("", "pair.txt"); });
  EXPECT_CONTAINS(e, "truncated");
}

// ------------------------------------------------------------------ PFM

// The four bytes of `value` in the requested byte order, independently of
// the host's.
std::string FloatBytes(float value, bool little_endian) {
  uint32_t bits;
  std::memcpy(&bits, &value, 4);
  std::string out(4, '\0');
  for (int i = 0; i < 4; ++i) {
    const auto byte = static_cast<char>((bits >> (8 * i)) & 0xFF);
    out[static_cast<size_t>(little_endian ? i : 3 - i)] = byte;
  }
  return out;
}

// A PFM whose data holds `file_order` as it appears in the file (bottom row
// first).
std::string PfmFromFileOrder(const std::string& magic, int w, int h, const std::string& scale,
                             const std::vector<float>& file_order) {
  std::string bytes = magic + "\n" + std::to_string(w) + " " + std::to_string(h) + "\n" + scale + "\n";
  const bool little = !scale.empty() && scale[0] == '-';
  for (float v : file_order) bytes += FloatBytes(v, little);
  return bytes;
}

// A 1-channel PFM of `top_first` (rows top to bottom), little-endian.
std::string DepthPfm(int w, int h, const std::vector<float>& top_first) {
  std::vector<float> file_order;
  for (int row = h - 1; row >= 0; --row) {
    for (int col = 0; col < w; ++col) file_order.push_back(top_first[static_cast<size_t>(row * w + col)]);
  }
  return PfmFromFileOrder("Pf", w, h, "-1.0", file_order);
}

TEST(PfmTest, RowsAreStoredBottomToTopInEitherByteOrder) {
  const std::vector<float> file_order{1.5f, 2.0f, 3.25f, 4.0f, 5.5f, -6.0f};  // 3 wide, 2 high
  const std::vector<float> top_first{4.0f, 5.5f, -6.0f, 1.5f, 2.0f, 3.25f};
  for (const std::string scale : {"-1.0", "1.0", "-0.5"}) {
    const PfmImage pfm = ParsePfm(PfmFromFileOrder("Pf", 3, 2, scale, file_order), "d.pfm");
    EXPECT_EQ(pfm.width, 3);
    EXPECT_EQ(pfm.height, 2);
    EXPECT_EQ(pfm.channels, 1);
    EXPECT_EQ(pfm.values, top_first) << "scale " << scale;
  }
  // The byte order is really honoured: the same bytes read big-endian differ.
  std::string le = PfmFromFileOrder("Pf", 3, 2, "-1.0", file_order);
  le.replace(le.find("-1.0"), 4, "+1.0");
  EXPECT_NE(ParsePfm(le, "d.pfm").values, top_first);

  const PfmImage colour = ParsePfm(PfmFromFileOrder("PF", 1, 2, "-1", {1, 2, 3, 4, 5, 6}), "c.pfm");
  EXPECT_EQ(colour.channels, 3);
  EXPECT_EQ(colour.values, (std::vector<float>{4, 5, 6, 1, 2, 3}));
}

TEST(PfmTest, WrongSizesAndHeadersAreErrors) {
  const std::vector<float> six{1, 2, 3, 4, 5, 6};
  std::string e = ErrorOf([&] { ParsePfm(PfmFromFileOrder("Pf", 3, 3, "-1.0", six), "d.pfm"); });
  EXPECT_CONTAINS(e, "d.pfm");
  EXPECT_CONTAINS(e, "needs 36 data bytes, found 24 (truncated)");
  e = ErrorOf([&] { ParsePfm(PfmFromFileOrder("Pf", 2, 2, "-1.0", six), "d.pfm"); });
  EXPECT_CONTAINS(e, "trailing data");
  e = ErrorOf([&] { ParsePfm(PfmFromFileOrder("P5", 3, 2, "-1.0", six), "d.pfm"); });
  EXPECT_CONTAINS(e, "not a PFM file");
  e = ErrorOf([&] { ParsePfm(PfmFromFileOrder("Pf", 3, 2, "0", six), "d.pfm"); });
  EXPECT_CONTAINS(e, "scale");
  e = ErrorOf([&] { ParsePfm("Pf\n3", "d.pfm"); });
  EXPECT_CONTAINS(e, "truncated PFM header");
  e = ErrorOf([&] { ParsePfm(PfmFromFileOrder("Pf", 0, 2, "-1", {}), "d.pfm"); });
  EXPECT_CONTAINS(e, "width");
}

TEST(PfmTest, DepthMapsMustBeFiniteNonNegativeOneChannel) {
  TempDir tmp;
  const fs::path good = tmp.path() / "good.pfm";
  WriteFileBytes(good, DepthPfm(2, 2, {0.0f, 1.0f, 2.0f, 3.0f}));
  const torch::Tensor depth = ReadMvsnetDepth(good);
  EXPECT_EQ(depth.sizes(), (std::vector<int64_t>{1, 2, 2}));
  EXPECT_EQ(depth[0][1][0].item<float>(), 2.0f);

  const fs::path nan = tmp.path() / "nan.pfm";
  WriteFileBytes(nan, DepthPfm(2, 2, {1.0f, std::numeric_limits<float>::quiet_NaN(), 2.0f, 3.0f}));
  std::string e = ErrorOf([&] { ReadMvsnetDepth(nan); });
  EXPECT_CONTAINS(e, nan.string());
  EXPECT_CONTAINS(e, "row 0, col 1");
  const fs::path negative = tmp.path() / "neg.pfm";
  WriteFileBytes(negative, DepthPfm(2, 2, {1.0f, 1.0f, -2.0f, 3.0f}));
  EXPECT_CONTAINS(ErrorOf([&] { ReadMvsnetDepth(negative); }), "row 1, col 0");
  const fs::path colour = tmp.path() / "colour.pfm";
  WriteFileBytes(colour, PfmFromFileOrder("PF", 1, 1, "-1", {1, 2, 3}));
  EXPECT_CONTAINS(ErrorOf([&] { ReadMvsnetDepth(colour); }), "one channel");
  EXPECT_CONTAINS(ErrorOf([&] { ReadMvsnetDepth(tmp.path() / "none.pfm"); }), "no such file");
}

// ------------------------------------------------------ fitting to the input size

std::array<double, 2> Project(const std::array<double, 9>& k, const std::array<double, 3>& p) {
  const double u = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
  const double v = k[3] * p[0] + k[4] * p[1] + k[5] * p[2];
  const double w = k[6] * p[0] + k[7] * p[1] + k[8] * p[2];
  return {u / w, v / w};
}

TEST(ViewFitTest, PlansResizeThenCentreCrop) {
  const ViewFit same_aspect = PlanViewFit(128, 160, 64, 80);
  EXPECT_EQ(same_aspect.resized_height, 64);
  EXPECT_EQ(same_aspect.resized_width, 80);
  EXPECT_EQ(same_aspect.crop_top, 0);
  EXPECT_EQ(same_aspect.crop_left, 0);
  EXPECT_EQ(same_aspect.scale_x, 0.5);

  const ViewFit taller = PlanViewFit(100, 120, 64, 80);  // width binds: 2/3
  EXPECT_EQ(taller.resized_width, 80);
  EXPECT_EQ(taller.resized_height, 67);
  EXPECT_EQ(taller.crop_top, 1);
  EXPECT_EQ(taller.crop_left, 0);
  EXPECT_DOUBLE_EQ(taller.scale_y, 0.67);
  EXPECT_DOUBLE_EQ(taller.scale_x, 80.0 / 120.0);

  const ViewFit wider = PlanViewFit(45, 100, 64, 80);  // height binds, upscaled
  EXPECT_EQ(wider.resized_height, 64);
  EXPECT_EQ(wider.resized_width, 142);
  EXPECT_EQ(wider.crop_left, 31);
  EXPECT_EQ(wider.height, 64);
  EXPECT_EQ(wider.width, 80);
}

// A 3D point seen through the fitted K lands where the original projection
// lands after the resize and crop, computed here from the definition of
// pixel-centre-aligned resampling: x' = (x + 0.5) * s - 0.5 - crop.
TEST(ViewFitTest, IntrinsicsFollowTheResizeExactly) {
  const std::array<double, 9> k{210.0, 0.75, 59.3, 0.0, 205.0, 48.7, 0.0, 0.0, 1.0};
  for (const auto& [h, w] : std::vector<std::pair<int64_t, int64_t>>{{100, 120}, {128, 160}, {45, 100}, {64, 80}}) {
    const ViewFit fit = PlanViewFit(h, w, 64, 80);
    const auto fitted = FitIntrinsics(k, fit);
    for (const std::array<double, 3>& p : {std::array<double, 3>{0.3, -0.2, 2.0}, {-1.0, 0.7, 5.5}, {0, 0, 1}}) {
      const auto original = Project(k, p);
      const auto moved = Project(fitted, p);
      EXPECT_NEAR(moved[0], (original[0] + 0.5) * (static_cast<double>(fit.resized_width) / w) - 0.5 -
                                static_cast<double>(fit.crop_left), 1e-9);
      EXPECT_NEAR(moved[1], (original[1] + 0.5) * (static_cast<double>(fit.resized_height) / h) - 0.5 -
                                static_cast<double>(fit.crop_top), 1e-9);
    }
  }
  // The usual shortcut (scale fx, cx alike) is off by (s - 1) / 2 pixel: the
  // exact form is not that.
  const auto half = FitIntrinsics(k, PlanViewFit(128, 160, 64, 80));
  EXPECT_DOUBLE_EQ(half[0], 105.0);
  EXPECT_DOUBLE_EQ(half[2], (59.3 + 0.5) * 0.5 - 0.5);
}

// The image resampling and the intrinsics agree: a ramp image whose
// channels hold each pixel's own (x, y) tells, after fitting, which original
// point each fitted pixel shows; K_original K_fitted^-1 must map the fitted
// pixel centre there.
TEST(ViewFitTest, ResampledImageMatchesFittedIntrinsics) {
  const std::array<double, 9> k{150.0, 0.0, 49.5, 0.0, 150.0, 22.0, 0.0, 0.0, 1.0};
  for (const auto& [h, w] : std::vector<std::pair<int64_t, int64_t>>{{45, 100}, {128, 160}, {64, 80}}) {
    const auto xs = torch::arange(w, torch::kDouble).view({1, 1, w}).expand({1, h, w});
    const auto ys = torch::arange(h, torch::kDouble).view({1, h, 1}).expand({1, h, w});
    const torch::Tensor ramp = torch::cat({xs, ys}).to(torch::kFloat);  // [2,h,w]
    const ViewFit fit = PlanViewFit(h, w, 64, 80);
    const torch::Tensor fitted = FitImage(ramp, fit);
    ASSERT_EQ(fitted.sizes(), (std::vector<int64_t>{2, 64, 80}));
    const auto kf = FitIntrinsics(k, fit);
    // Away from the border, where the resampling clamps.
    for (int64_t i = 4; i < 60; i += 5) {
      for (int64_t j = 4; j < 76; j += 7) {
        // Fitted pixel (j, i) back to the original image through the two K:
        // a point on its ray at depth 1.
        const double yn = (static_cast<double>(i) - kf[5]) / kf[4];
        const double xn = (static_cast<double>(j) - kf[2] - kf[1] * yn) / kf[0];
        const auto original = Project(k, {xn, yn, 1.0});
        EXPECT_NEAR(fitted[0][i][j].item<float>(), original[0], 1e-3) << h << "x" << w << " at " << i << "," << j;
        EXPECT_NEAR(fitted[1][i][j].item<float>(), original[1], 1e-3) << h << "x" << w << " at " << i << "," << j;
      }
    }
  }
}

TEST(ViewFitTest, DepthTakesTheNearestPixelAndKeepsHoles) {
  // d(i, j) = 10 i + j + 1, with a hole.
  auto depth = (torch::arange(4, torch::kFloat).view({1, 4, 1}) * 10 + torch::arange(4, torch::kFloat).view({1, 1, 4}) + 1)
                   .contiguous();
  depth[0][3][3] = 0;
  const torch::Tensor fitted = FitDepth(depth, PlanViewFit(4, 4, 2, 2));
  // Fitted centre i is at stored (i + 0.5) * 2 - 0.5 = 2i + 0.5: stored 2i + 1.
  EXPECT_EQ(fitted[0][0][0].item<float>(), 12.0f);
  EXPECT_EQ(fitted[0][0][1].item<float>(), 14.0f);
  EXPECT_EQ(fitted[0][1][0].item<float>(), 32.0f);
  EXPECT_EQ(fitted[0][1][1].item<float>(), 0.0f);
  // Upscaled and cropped: 2x4 -> 4x4 (resized 4x8, crop_left 2).
  const torch::Tensor up = FitDepth(depth.narrow(1, 0, 2), PlanViewFit(2, 4, 4, 4));
  EXPECT_EQ(up[0][0][0].item<float>(), 2.0f);  // resized col 2 -> stored col 1
  EXPECT_EQ(up[0][3][3].item<float>(), 13.0f);  // resized row 3, col 5 -> stored 1, 2
}

// ------------------------------------------------------------------ data sets

TEST(ChooseMvsnetViewTest, DeterministicFromTheSeedWithTheRequestedFraction) {
  int chosen = 0;
  std::set<size_t> indices;
  for (uint64_t seed = 0; seed < 4000; ++seed) {
    EXPECT_FALSE(ChooseMvsnetView(seed, 0.0, 5).has_value());
    const auto always = ChooseMvsnetView(seed, 1.0, 5);
    ASSERT_TRUE(always.has_value());
    EXPECT_LT(*always, 5u);
    indices.insert(*always);
    const auto some = ChooseMvsnetView(seed, 0.3, 5);
    EXPECT_EQ(some, ChooseMvsnetView(seed, 0.3, 5));
    chosen += some.has_value();
  }
  EXPECT_EQ(indices.size(), 5u);
  EXPECT_NEAR(chosen / 4000.0, 0.3, 0.03);
  EXPECT_FALSE(ChooseMvsnetView(1, 1.0, 0).has_value());
  EXPECT_THROW(ChooseMvsnetView(1, 1.5, 3), std::invalid_argument);
}

// A tiny scan: 3 views of 160x128 looking down +z with a 50-unit baseline, a
// depth map for views 0 and 1 (a plane at 600 + row / 2 with a hole), cams
// with range 425 .. 902.5. View v's blue channel is 20 + 50 v everywhere.
constexpr int kH = 128, kW = 160;

std::string TinyCam(double center_x) {
  std::ostringstream rows;
  rows << "1 0 0 " << -center_x << "\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";
  return CamText(rows.str(), "200 0 79.5\n0 200 63.5\n0 0 1\n", "425 2.5");
}

float TinyDepth(int row, int col) {
  if (row >= 10 && row < 20 && col >= 30 && col < 40) return 0.0f;  // no ground truth
  return 600.0f + 0.5f * static_cast<float>(row);
}

void WriteTinyScan(const fs::path& dir, bool with_images = true) {
  WriteFileBytes(dir / "pair.txt", "3\n0\n2 1 9.5 2 4.0\n1\n2 0 9.5 2 1.0\n2\n1 0 4.0\n");
  const double centers[3] = {0.0, 50.0, -50.0};
  std::vector<float> depth;
  for (int i = 0; i < kH; ++i) {
    for (int j = 0; j < kW; ++j) depth.push_back(TinyDepth(i, j));
  }
  for (int v = 0; v < 3; ++v) {
    char name[32];
    std::snprintf(name, sizeof name, "%08d", v);
    WriteFileBytes(dir / "cams" / (std::string(name) + "_cam.txt"), TinyCam(centers[v]));
    if (v < 2) WriteFileBytes(dir / "depths" / (std::string(name) + ".pfm"), DepthPfm(kW, kH, depth));
#ifdef DISPMVS_HAVE_OPENCV
    if (with_images) {
      cv::Mat bgr(kH, kW, CV_8UC3);
      for (int i = 0; i < kH; ++i) {
        for (int j = 0; j < kW; ++j) {
          // Texture in red and green (shifted per view like a stereo pair).
          const int x = j + 8 * v;
          bgr.at<cv::Vec3b>(i, j) = cv::Vec3b(static_cast<uchar>(20 + 50 * v), static_cast<uchar>((x * 37 + i * 11) % 256),
                                               static_cast<uchar>(((x / 4 + i / 4) % 2) * 200 + 20));
        }
      }
      fs::create_directories(dir / "images");
      ASSERT_TRUE(cv::imwrite((dir / "images" / (std::string(name) + ".png")).string(), bgr));
    }
#else
    // Nothing can decode images here: a placeholder, so that the layout
    // (which only looks for the files) is still complete.
    if (with_images) WriteFileBytes(dir / "images" / (std::string(name) + ".png"), "");
#endif
  }
}

TEST(MvsnetDatasetTest, OpensAScanAndListsTrainingViews) {
  if (!MvsnetImageDecodingAvailable()) GTEST_SKIP() << "built without OpenCV";
  TempDir tmp;
  WriteTinyScan(tmp.path() / "scan1");
  // A root of scans, and a scan as the root: the same scan.
  for (const fs::path& root : {tmp.path(), tmp.path() / "scan1"}) {
    const MvsnetDataset ds = OpenMvsnetDataset(root);
    ASSERT_EQ(ds.scans.size(), 1u);
    const MvsnetScan& scan = ds.scans[0];
    EXPECT_EQ(scan.name, "scan1");
    ASSERT_EQ(scan.pairs.size(), 3u);
    EXPECT_EQ(scan.cameras[1].world_to_camera[3], -50.0);
    EXPECT_EQ(scan.images[2].filename(), "00000002.png");
    EXPECT_EQ(scan.depths[1].filename(), "00000001.pfm");
    EXPECT_TRUE(scan.depths[2].empty());
    // With one source: views 0 and 1 (2 has no depth); with two: still both.
    const auto one = MvsnetTrainingViews(ds, 1);
    ASSERT_EQ(one.size(), 2u);
    EXPECT_EQ(scan.pairs[one[0].pair].reference, 0);
    EXPECT_EQ(scan.pairs[one[1].pair].reference, 1);
    EXPECT_EQ(MvsnetTrainingViews(ds, 2).size(), 2u);
    EXPECT_EQ(MvsnetTrainingViews(ds, 3).size(), 0u);
  }
}

TEST(MvsnetDatasetTest, SampleIsFittedAndLaidOutLikeAGeneratedOne) {
  if (!MvsnetImageDecodingAvailable()) GTEST_SKIP() << "built without OpenCV";
  TempDir tmp;
  WriteTinyScan(tmp.path());
  const MvsnetDataset ds = OpenMvsnetDataset(tmp.path());
  MvsnetSampleOptions options;
  options.height = 64;
  options.width = 80;
  options.num_sources = 2;
  const auto sample = LoadMvsnetSample(ds, {0, 0}, options, torch::kCPU);
  EXPECT_EQ(sample.images.sizes(), (std::vector<int64_t>{3, 3, 64, 80}));
  EXPECT_EQ(sample.intrinsics.sizes(), (std::vector<int64_t>{3, 3, 3}));
  EXPECT_EQ(sample.world_to_camera.sizes(), (std::vector<int64_t>{3, 4, 4}));
  EXPECT_EQ(sample.depths.sizes(), (std::vector<int64_t>{3, 1, 64, 80}));
  EXPECT_EQ(sample.images.scalar_type(), torch::kFloat);
  EXPECT_EQ(sample.depth_min, 425.0);
  EXPECT_EQ(sample.depth_max, 902.5);
  EXPECT_EQ(sample.rig, "mvsnet");

  // Views in the order reference, sources of pair.txt: 0, 1, 2.
  EXPECT_EQ(sample.world_to_camera[1][0][3].item<float>(), -50.0f);
  EXPECT_EQ(sample.world_to_camera[2][0][3].item<float>(), 50.0f);
  // Half size: fx = 100, cx = (79.5 + 0.5) / 2 - 0.5 = 39.5.
  EXPECT_FLOAT_EQ(sample.intrinsics[0][0][0].item<float>(), 100.0f);
  EXPECT_FLOAT_EQ(sample.intrinsics[0][0][2].item<float>(), 39.5f);
  EXPECT_FLOAT_EQ(sample.intrinsics[0][1][2].item<float>(), 31.5f);
  // RGB order: OpenCV's blue is channel 2; view v's is 20 + 50 v.
  for (int v = 0; v < 3; ++v) {
    const auto blue = sample.images[v][2];
    EXPECT_NEAR(blue.min().item<float>(), (20 + 50 * v) / 255.0f, 1e-6) << v;
    EXPECT_NEAR(blue.max().item<float>(), (20 + 50 * v) / 255.0f, 1e-6) << v;
  }
  EXPECT_GE(sample.images.min().item<float>(), 0.0f);
  EXPECT_LE(sample.images.max().item<float>(), 1.0f);
  // Reference depth: fitted pixel (i, j) is stored (2i + 1, 2j + 1), rows the
  // right way up; the hole stays 0. Sources: 0 (not read).
  EXPECT_EQ(sample.depths[0][0][0][0].item<float>(), TinyDepth(1, 1));
  EXPECT_EQ(sample.depths[0][0][40][7].item<float>(), TinyDepth(81, 15));
  EXPECT_EQ(sample.depths[0][0][7][17].item<float>(), 0.0f);  // stored (15, 35)
  EXPECT_EQ(sample.depths[1].abs().max().item<float>(), 0.0f);
  EXPECT_EQ(sample.depths[2].abs().max().item<float>(), 0.0f);

  options.source_depths = true;
  const auto with_sources = LoadMvsnetSample(ds, {0, 0}, options, torch::kCPU);
  EXPECT_EQ(with_sources.depths[1][0][0][0].item<float>(), TinyDepth(1, 1));
  EXPECT_EQ(with_sources.depths[2].abs().max().item<float>(), 0.0f);  // view 2 has none

  options.num_sources = 3;
  EXPECT_THROW(LoadMvsnetSample(ds, {0, 0}, options, torch::kCPU), std::invalid_argument);
}

TEST(MvsnetDatasetTest, BrokenDataSetsAreClearErrors) {
  TempDir tmp;
  // pair.txt names a view 3 that has no camera file.
  const fs::path missing_view = tmp.path() / "missing_view";
  WriteTinyScan(missing_view);
  WriteFileBytes(missing_view / "pair.txt", "4\n0\n1 1 1\n1\n1 0 1\n2\n1 0 1\n3\n1 0 1\n");
  std::string e = ErrorOf([&] { OpenMvsnetDataset(missing_view); });
  EXPECT_CONTAINS(e, "pair.txt: view 3 has no camera file");
  EXPECT_CONTAINS(e, "00000003_cam.txt");

  // A source index beyond the view count.
  WriteFileBytes(missing_view / "pair.txt", "3\n0\n1 7 1\n1\n1 0 1\n2\n1 0 1\n");
  e = ErrorOf([&] { OpenMvsnetDataset(missing_view); });
  EXPECT_CONTAINS(e, "pair.txt:3: view 7 out of range");

  // A truncated cam.txt surfaces when the data set is opened.
  const fs::path bad_cam = tmp.path() / "bad_cam";
  WriteTinyScan(bad_cam);
  const std::string cam = TinyCam(0.0);
  WriteFileBytes(bad_cam / "cams" / "00000001_cam.txt", cam.substr(0, cam.find("intrinsic")));
  e = ErrorOf([&] { OpenMvsnetDataset(bad_cam); });
  EXPECT_CONTAINS(e, "00000001_cam.txt: truncated");

  EXPECT_CONTAINS(ErrorOf([&] { OpenMvsnetDataset(tmp.path() / "nothing"); }), "not a folder");
  fs::create_directories(tmp.path() / "empty" / "sub");
  EXPECT_CONTAINS(ErrorOf([&] { OpenMvsnetDataset(tmp.path() / "empty"); }), "no MVSNet scan");

  // A view without an image.
  const fs::path no_image = tmp.path() / "no_image";
  WriteTinyScan(no_image);
  fs::remove(no_image / "images" / "00000002.png");
  EXPECT_CONTAINS(ErrorOf([&] { OpenMvsnetDataset(no_image); }), "view 2 has no image");

  if (!MvsnetImageDecodingAvailable()) {
    // The rest needs decoded images; what matters here is the refusal.
    EXPECT_CONTAINS(ErrorOf([] { RequireMvsnetImageDecoding(); }), "built without OpenCV");
    return;
  }

  // A depth map of the wrong size for its image.
  const fs::path wrong_size = tmp.path() / "wrong_size";
  WriteTinyScan(wrong_size);
  WriteFileBytes(wrong_size / "depths" / "00000000.pfm", DepthPfm(3, 2, {1, 2, 3, 4, 5, 6}));
  const MvsnetDataset ds = OpenMvsnetDataset(wrong_size);
  MvsnetSampleOptions options;
  options.height = 64;
  options.width = 80;
  options.num_sources = 1;
  e = ErrorOf([&] { LoadMvsnetSample(ds, {0, 0}, options, torch::kCPU); });
  EXPECT_CONTAINS(e, "00000000.pfm: depth map is 3x2");
  EXPECT_CONTAINS(e, "is 160x128");
}

// ------------------------------------------------------------------ trainer

TrainOptions TinyMvsnetOptions(const fs::path& root, const fs::path& checkpoints, int64_t steps) {
  TrainOptions o;
  o.config = "small";
  o.height = 64;
  o.width = 80;
  o.num_sources = 1;
  o.steps = steps;
  o.threads = 1;
  o.checkpoint_dir = checkpoints.string();
  o.checkpoint_every = 2;
  o.num_validation_scenes = 1;  // validation stays on generated scenes
  o.mvsnet_root = root.string();
  return o;
}

TEST(MvsnetTrainingTest, OptionsAreChecked) {
  TrainOptions o;
  o.checkpoint_dir = "unused";
  o.mvsnet_fraction = 0.5;
  EXPECT_THROW(o.Check(), std::invalid_argument);  // no data set
  o.mvsnet_root = "somewhere";
  EXPECT_NO_THROW(o.Check());
  for (double bad : {-0.1, 1.5, std::numeric_limits<double>::quiet_NaN()}) {
    o.mvsnet_fraction = bad;
    EXPECT_THROW(o.Check(), std::invalid_argument) << bad;
  }
}

TEST(MvsnetTrainingTest, TrainsOnTheDataSetAndRefusesToResumeWithOtherData) {
  if (!MvsnetImageDecodingAvailable()) GTEST_SKIP() << "built without OpenCV";
  TempDir tmp;
  const fs::path root = tmp.path() / "data";
  WriteTinyScan(root / "scan1");
  const fs::path run = tmp.path() / "run";
  std::ostringstream log;
  Train(TinyMvsnetOptions(root, run, 2), log);
  EXPECT_CONTAINS(log.str(), "MVSNet data set");
  EXPECT_CONTAINS(log.str(), "1 scans, 2 reference views");
  EXPECT_CONTAINS(log.str(), "step 2/2");
  EXPECT_CONTAINS(log.str(), "validate step 2");
  EXPECT_EQ(log.str().find("loss nan"), std::string::npos) << log.str();
  EXPECT_EQ(log.str().find("loss -nan"), std::string::npos) << log.str();
  EXPECT_TRUE(fs::exists(run / "checkpoint-000000002.safetensors"));
  EXPECT_TRUE(fs::exists(run / "checkpoint-000000002.optim.safetensors"));
  EXPECT_TRUE(fs::exists(run / "model.safetensors"));

  // Resuming with another fraction, or without the data set, is refused ...
  auto other = TinyMvsnetOptions(root, run, 4);
  other.mvsnet_fraction = 0.5;
  std::ostringstream ignored;
  EXPECT_CONTAINS(ErrorOf([&] { Train(other, ignored); }), "mvsnet_fraction");
  other = TinyMvsnetOptions(root, run, 4);
  other.mvsnet_root.clear();
  EXPECT_CONTAINS(ErrorOf([&] { Train(other, ignored); }), "mvsnet_root");
  // ... the same settings resume ...
  std::ostringstream resumed;
  Train(TinyMvsnetOptions(root, run, 3), resumed);
  EXPECT_CONTAINS(resumed.str(), "at step 2");
  EXPECT_CONTAINS(resumed.str(), "step 3/3");
  // ... and a data set without training views is an error before any step.
  const fs::path no_depth = tmp.path() / "no_depth";
  WriteTinyScan(no_depth);
  fs::remove_all(no_depth / "depths");
  EXPECT_CONTAINS(ErrorOf([&] { Train(TinyMvsnetOptions(no_depth, tmp.path() / "run2", 1), ignored); }),
                  "no reference view with a ground-truth depth map");
}

// Checkpoints written before the data set options existed have no such
// settings: they were trained on generated scenes alone and resume as such.
TEST(MvsnetTrainingTest, CheckpointsFromBeforeTheOptionsResumeWithoutADataSet) {
  TempDir tmp;
  const fs::path run = tmp.path() / "run";
  auto options = TinyMvsnetOptions("", run, 2);
  options.num_validation_scenes = 0;
  std::ostringstream log;
  Train(options, log);
  const std::string optim = (run / "checkpoint-000000002.optim.safetensors").string();
  auto file = model::LoadSafetensors(optim);
  ASSERT_EQ(file.metadata.at("mvsnet_root"), "");
  ASSERT_EQ(file.metadata.at("mvsnet_fraction"), "1");
  file.metadata.erase("mvsnet_root");
  file.metadata.erase("mvsnet_fraction");
  model::SaveSafetensors(optim, file.tensors, file.metadata);

  auto with_data = TinyMvsnetOptions(tmp.path() / "data", run, 3);
  with_data.num_validation_scenes = 0;
  std::ostringstream ignored;
  EXPECT_CONTAINS(ErrorOf([&] { Train(with_data, ignored); }), "mvsnet_root is ''");
  options.steps = 3;
  std::ostringstream resumed;
  Train(options, resumed);
  EXPECT_CONTAINS(resumed.str(), "at step 2");
}

}  // namespace
}  // namespace dispmvs::train
