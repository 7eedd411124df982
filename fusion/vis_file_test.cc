#include "fusion/vis_file.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "fusion/fused_cloud_writer.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::fusion {
namespace {

using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::TempDir;
using dispmvs::testing::WriteFileBytes;

FusedPoint PointWith(std::vector<uint32_t> visibility) {
  FusedPoint point;
  point.visibility = std::move(visibility);
  return point;
}

// Three points seen by {3, 7}, nobody, and {0x01020304}, as COLMAP lays them
// out: uint64 count, then per point uint32 n and n uint32 indices, all little
// endian.
std::vector<FusedPoint> SamplePoints() {
  return {PointWith({3, 7}), PointWith({}), PointWith({0x01020304u})};
}

std::string SampleBytes() {
  return std::string(
      "\x03\x00\x00\x00\x00\x00\x00\x00"  // 3 points
      "\x02\x00\x00\x00"                  // point 0: 2 images
      "\x03\x00\x00\x00\x07\x00\x00\x00"  //   3, 7
      "\x00\x00\x00\x00"                  // point 1: none
      "\x01\x00\x00\x00"                  // point 2: 1 image
      "\x04\x03\x02\x01",                 //   0x01020304
      32);
}

TEST(VisFileTest, ByteLayoutMatchesColmap) {
  TempDir dir;
  const auto path = dir.path() / "fused.ply.vis";
  WriteVisibilityFile(SamplePoints(), path);
  EXPECT_EQ(ReadFileBytes(path), SampleBytes());
}

TEST(VisFileTest, EmptyCloudIsJustTheCount) {
  TempDir dir;
  const auto path = dir.path() / "empty.vis";
  WriteVisibilityFile({}, path);
  EXPECT_EQ(ReadFileBytes(path), std::string(8, '\0'));
  EXPECT_TRUE(ReadVisibilityFile(path).empty());
}

TEST(VisFileTest, ReadsHandBuiltBytes) {
  TempDir dir;
  const auto path = dir.path() / "hand.vis";
  WriteFileBytes(path, SampleBytes());
  const std::vector<std::vector<uint32_t>> expected = {{3, 7}, {}, {0x01020304u}};
  EXPECT_EQ(ReadVisibilityFile(path), expected);
}

TEST(VisFileTest, FusedPointCloudRoundTrip) {
  TempDir dir;
  const auto ply_path = dir.path() / "sub" / "fused.ply";
  std::vector<FusedPoint> points = SamplePoints();
  for (std::size_t i = 0; i < points.size(); ++i) {
    points[i].xyz = Eigen::Vector3f(1.5f * i, -2.0f, 0.25f + i);
    points[i].normal = Eigen::Vector3f(0, 0.6f, -0.8f);
    points[i].rgb = {static_cast<uint8_t>(10 * i), 200, 255};
  }
  WriteFusedPointCloud(points, ply_path);

  const std::vector<colmap_io::PlyPoint> ply = colmap_io::ReadPlyPoints(ply_path);
  ASSERT_EQ(ply.size(), points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(ply[i].xyz[c], points[i].xyz[c]);
      EXPECT_EQ(ply[i].normal[c], points[i].normal[c]);
    }
    EXPECT_EQ(ply[i].rgb, points[i].rgb);
  }
  const auto vis_path = dir.path() / "sub" / "fused.ply.vis";
  EXPECT_EQ(ReadFileBytes(vis_path), SampleBytes());
  const std::vector<std::vector<uint32_t>> visibility = ReadVisibilityFile(vis_path);
  ASSERT_EQ(visibility.size(), points.size());
  for (std::size_t i = 0; i < points.size(); ++i) EXPECT_EQ(visibility[i], points[i].visibility);
}

TEST(VisFileTest, LargerRoundTrip) {
  TempDir dir;
  const auto path = dir.path() / "many.vis";
  std::vector<FusedPoint> points;
  for (uint32_t i = 0; i < 50000; ++i) points.push_back(PointWith({i % 7, i, 0xFFFFFFFFu - i}));
  WriteVisibilityFile(points, path);
  const std::vector<std::vector<uint32_t>> visibility = ReadVisibilityFile(path);
  ASSERT_EQ(visibility.size(), points.size());
  for (std::size_t i = 0; i < points.size(); ++i) ASSERT_EQ(visibility[i], points[i].visibility);
}

// Every error names the file.
void ExpectIoError(const std::filesystem::path& path, const std::string& bytes) {
  WriteFileBytes(path, bytes);
  try {
    ReadVisibilityFile(path);
    ADD_FAILURE() << "no error for " << bytes.size() << " bytes";
  } catch (const colmap_io::IoError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
  }
}

TEST(VisFileTest, EveryTruncationIsAnError) {
  TempDir dir;
  const auto path = dir.path() / "cut.vis";
  const std::string bytes = SampleBytes();
  for (std::size_t size = 0; size < bytes.size(); ++size) ExpectIoError(path, bytes.substr(0, size));
}

TEST(VisFileTest, TrailingBytesAreAnError) {
  TempDir dir;
  ExpectIoError(dir.path() / "long.vis", SampleBytes() + std::string(1, '\0'));
}

TEST(VisFileTest, HugeCountsFailBeforeAllocating) {
  TempDir dir;
  // 2^64 - 1 points in a 12-byte file.
  ExpectIoError(dir.path() / "points.vis", std::string(8, '\xFF') + std::string(4, '\0'));
  // One point listing 2^32 - 1 images.
  ExpectIoError(dir.path() / "images.vis",
                std::string("\x01\x00\x00\x00\x00\x00\x00\x00", 8) + std::string(4, '\xFF') +
                    std::string(8, '\0'));
}

TEST(VisFileTest, MissingFileIsAnError) {
  TempDir dir;
  EXPECT_THROW(ReadVisibilityFile(dir.path() / "absent.vis"), colmap_io::IoError);
}

TEST(VisFileTest, StreamErrorsNameTheSource) {
  std::istringstream in(std::string("\x02\x00\x00\x00\x00\x00\x00\x00", 8));
  try {
    ReadVisibilityFile(in, "my-source");
    ADD_FAILURE() << "no error";
  } catch (const colmap_io::IoError& e) {
    EXPECT_EQ(e.path(), "my-source");
  }
}

// The streaming writer behind WriteFusedPointCloud: identical files for a
// cloud larger than its 1 MB buffers, its body files gone afterwards, and
// nothing under the final names when it is dropped before Finish().
TEST(FusedCloudWriterTest, StreamsTheSameFilesAndLeavesNothingBehind) {
  TempDir dir;
  std::vector<FusedPoint> points;
  for (uint32_t i = 0; i < 60000; ++i) {
    points.push_back(PointWith({i % 5, i, i + 7}));
    points.back().xyz = Eigen::Vector3f(static_cast<float>(i), 0.5f, -1.0f);
  }
  const auto ply = dir.path() / "fused.ply";
  {
    FusedCloudWriter writer(ply);
    for (const FusedPoint& point : points) writer.Add(point);
    EXPECT_EQ(writer.size(), points.size());
    writer.Finish();
  }
  const std::vector<colmap_io::PlyPoint> read = colmap_io::ReadPlyPoints(ply);
  ASSERT_EQ(read.size(), points.size());
  EXPECT_EQ(read[59999].xyz[0], 59999.0f);
  const auto visibility = ReadVisibilityFile(dir.path() / "fused.ply.vis");
  ASSERT_EQ(visibility.size(), points.size());
  EXPECT_EQ(visibility[12345], points[12345].visibility);
  std::size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    (void)entry;
    ++files;
  }
  EXPECT_EQ(files, 2u);  // fused.ply and fused.ply.vis only

  TempDir dropped;
  {
    FusedCloudWriter writer(dropped.path() / "fused.ply");
    writer.Add(points[0]);
  }
  EXPECT_TRUE(std::filesystem::is_empty(dropped.path()));
}

}  // namespace
}  // namespace dispmvs::fusion
