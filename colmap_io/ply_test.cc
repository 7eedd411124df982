#include "colmap_io/ply.h"

#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

using testing::ReadFileBytes;
using testing::TempDir;
using testing::WriteFileBytes;

const std::string kHeader =
    "ply\n"
    "format binary_little_endian 1.0\n"
    "element vertex 1\n"
    "property float x\nproperty float y\nproperty float z\n"
    "property float nx\nproperty float ny\nproperty float nz\n"
    "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    "end_header\n";

// One point: xyz (1, -2, 0.5), normal (0, 0, 1), colour (10, 200, 255).
// IEEE-754 single precision, little endian, worked out by hand:
//   1.0f = 0x3F800000, -2.0f = 0xC0000000, 0.5f = 0x3F000000, 0.0f = 0.
const std::string kBody = std::string(
    "\x00\x00\x80\x3F"
    "\x00\x00\x00\xC0"
    "\x00\x00\x00\x3F"
    "\x00\x00\x00\x00"
    "\x00\x00\x00\x00"
    "\x00\x00\x80\x3F"
    "\x0A\xC8\xFF",
    27);

PlyPoint HandBuiltPoint() {
  PlyPoint point;
  point.xyz = {1.0f, -2.0f, 0.5f};
  point.normal = {0.0f, 0.0f, 1.0f};
  point.rgb = {10, 200, 255};
  return point;
}

TEST(PlyTest, WritesColmapFusedPlyLayoutByteForByte) {
  TempDir dir;
  const auto path = dir.path() / "one.ply";
  WritePlyPoints({HandBuiltPoint()}, path);
  EXPECT_EQ(ReadFileBytes(path), kHeader + kBody);
}

TEST(PlyTest, ReadsHandBuiltFile) {
  TempDir dir;
  const auto path = dir.path() / "one.ply";
  // A comment line, as other writers add, must be skipped.
  std::string with_comment = kHeader;
  with_comment.insert(with_comment.find("element"), "comment made by hand\n");
  WriteFileBytes(path, with_comment + kBody);
  const std::vector<PlyPoint> points = ReadPlyPoints(path);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points[0], HandBuiltPoint());
}

TEST(PlyTest, RoundTripIsExact) {
  std::vector<PlyPoint> points;
  for (int i = 0; i < 100; ++i) {
    PlyPoint p;
    p.xyz = {i * 0.1f - 3.0f, 1e-7f * i, -1e6f + i};
    p.normal = {0.6f, -0.8f, i % 2 ? 0.0f : -0.0f};
    p.rgb = {static_cast<uint8_t>(i), static_cast<uint8_t>(255 - i), static_cast<uint8_t>(i * 7)};
    points.push_back(p);
  }
  TempDir dir;
  const auto path = dir.path() / "sub" / "cloud.ply";
  WritePlyPoints(points, path);
  EXPECT_EQ(ReadFileBytes(path).size(), kHeader.size() + 2 /* "100" vs "1" */ + 100 * 27);
  EXPECT_EQ(ReadPlyPoints(path), points);

  WritePlyPoints({}, path);
  EXPECT_TRUE(ReadPlyPoints(path).empty());
}

TEST(PlyTest, RejectsOtherLayoutsAndBadSizes) {
  auto read = [](const std::string& bytes) {
    std::istringstream in(bytes);
    return ReadPlyPoints(in, "test.ply");
  };
  EXPECT_THROW(read(""), IoError);
  EXPECT_THROW(read("obj\n"), IoError);
  std::string ascii = kHeader;
  ascii.replace(ascii.find("binary_little_endian"), 20, "ascii");
  EXPECT_THROW(read(ascii + kBody), IoError);
  std::string no_normals = kHeader;
  no_normals.erase(no_normals.find("property float nx"), 54);
  EXPECT_THROW(read(no_normals + kBody), IoError);
  EXPECT_THROW(read(kHeader + kBody.substr(0, 26)), IoError);  // truncated
  EXPECT_THROW(read(kHeader + kBody + "x"), IoError);          // trailing byte
  std::string huge = kHeader;
  huge.replace(huge.find("vertex 1"), 8, "vertex 9999999999999999999");
  EXPECT_THROW(read(huge + kBody), IoError);  // would not fit: rejected before allocating
  std::string negative = kHeader;
  negative.replace(negative.find("vertex 1"), 8, "vertex -1");
  EXPECT_THROW(read(negative + kBody), IoError);
  try {
    read(kHeader);
    FAIL() << "expected IoError";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("test.ply"), std::string::npos);
  }
  TempDir dir;
  EXPECT_THROW(ReadPlyPoints(dir.path() / "missing.ply"), IoError);
}

}  // namespace
}  // namespace dispmvs::colmap_io
