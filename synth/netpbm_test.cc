// Binary PPM/PGM decoding: samples, header forms and refusals, checked
// against bytes written by hand.

#include "synth/netpbm.h"

#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "tests/support/temp_dir.h"

namespace dispmvs::synth {
namespace {

using testing::TempDir;

std::string Write(const TempDir& tmp, const std::string& name, const std::string& bytes) {
  const std::string path = (tmp.path() / name).string();
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

std::string ErrorOf(const std::string& path) {
  try {
    ReadNetpbm(path);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "(accepted)";
}

TEST(NetpbmTest, ColourSamplesInRowMajorOrderWithComments) {
  TempDir tmp;
  // 2 x 1 pixels: (255, 0, 51) and (0, 102, 255); a comment in the header.
  const std::string pixels{'\xff', '\x00', '\x33', '\x00', '\x66', '\xff'};
  const auto image = ReadNetpbm(Write(tmp, "a.ppm", "P6\n# made by hand\n2 1\n255\n" + pixels));
  ASSERT_EQ(image.sizes(), torch::IntArrayRef({3, 1, 2}));
  EXPECT_FLOAT_EQ(image[0][0][0].item<float>(), 1.0f);
  EXPECT_FLOAT_EQ(image[1][0][0].item<float>(), 0.0f);
  EXPECT_FLOAT_EQ(image[2][0][0].item<float>(), 0.2f);
  EXPECT_FLOAT_EQ(image[0][0][1].item<float>(), 0.0f);
  EXPECT_FLOAT_EQ(image[1][0][1].item<float>(), 0.4f);
  EXPECT_FLOAT_EQ(image[2][0][1].item<float>(), 1.0f);
}

TEST(NetpbmTest, SixteenBitGreyIsBigEndianAndReplicated) {
  TempDir tmp;
  // 1 x 2 pixels, maxval 1000: 500 (0x01f4) above 1000 (0x03e8).
  const std::string samples{'\x01', '\xf4', '\x03', '\xe8'};
  const auto image = ReadNetpbm(Write(tmp, "g.pgm", "P5 1 2 1000\n" + samples));
  ASSERT_EQ(image.sizes(), torch::IntArrayRef({3, 2, 1}));
  for (int c = 0; c < 3; ++c) {
    EXPECT_FLOAT_EQ(image[c][0][0].item<float>(), 0.5f);
    EXPECT_FLOAT_EQ(image[c][1][0].item<float>(), 1.0f);
  }
}

TEST(NetpbmTest, BadFilesAreRefusedWithTheReason) {
  TempDir tmp;
  EXPECT_NE(ErrorOf((tmp.path() / "missing.ppm").string()).find("cannot open"), std::string::npos);
  EXPECT_NE(ErrorOf(Write(tmp, "ascii.ppm", "P3\n1 1\n255\n0 0 0\n")).find("not a binary PPM"), std::string::npos);
  EXPECT_NE(ErrorOf(Write(tmp, "png.ppm", "\x89PNG....")).find("not a binary PPM"), std::string::npos);
  EXPECT_NE(ErrorOf(Write(tmp, "size.ppm", "P6\n0 1\n255\n")).find("width or height"), std::string::npos);
  EXPECT_NE(ErrorOf(Write(tmp, "max.ppm", "P6\n1 1\n0\nabc")).find("maxval"), std::string::npos);
  EXPECT_NE(ErrorOf(Write(tmp, "header.ppm", "P6\n1 1\n255")).find("truncated header"), std::string::npos);
  EXPECT_NE(ErrorOf(Write(tmp, "short.ppm", "P6\n2 2\n255\nabcdef")).find("truncated: 6 sample bytes, expected 12"),
            std::string::npos);
  EXPECT_NE(ErrorOf(Write(tmp, "over.pgm", "P5\n1 1\n100\n\xc8")).find("exceeds maxval"), std::string::npos);
}

}  // namespace
}  // namespace dispmvs::synth
