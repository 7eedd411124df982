#include "colmap_io/view_record.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

namespace fs = std::filesystem;
using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::TempDir;
using dispmvs::testing::WriteFileBytes;

Workspace MakeWorkspace(const TempDir& dir) {
  fs::create_directories(dir.path() / "ws" / "images");
  fs::create_directories(dir.path() / "ws" / "sparse");
  return Workspace(dir.path() / "ws");
}

TEST(ViewRecordTest, WritesTheDocumentedLinesAndReadsThemBack) {
  TempDir dir;
  const Workspace workspace = MakeWorkspace(dir);
  const fs::path path = ViewRecordPath(workspace, "sub/a b.jpg");
  EXPECT_EQ(path, dir.path() / "ws" / "stereo" / "dispmvs_records" / "sub" / "a b.jpg.txt");
  ViewRecord record;
  record.seconds = 1.25;
  record.width = 640;
  record.height = 480;
  record.num_sources = 4;
  record.device = "cuda:1";
  WriteViewRecord(path, record);
  EXPECT_EQ(ReadFileBytes(path), "seconds 1.250000\nsize 640x480\nsources 4\ndevice cuda:1\n");
  const auto back = ReadViewRecord(path);
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->seconds, 1.25);
  EXPECT_EQ(back->width, 640);
  EXPECT_EQ(back->height, 480);
  EXPECT_EQ(back->num_sources, 4);
  EXPECT_EQ(back->device, "cuda:1");
}

TEST(ViewRecordTest, AFailedViewIsOneLineWithItsReason) {
  TempDir dir;
  const fs::path path = dir.path() / "failed.txt";
  ViewRecord record;
  record.seconds = 3;  // ignored: a failed view has only its reason
  record.failure = "ws/images/a.png: JPEG file is truncated\nsecond line";
  WriteViewRecord(path, record);
  EXPECT_EQ(ReadFileBytes(path), "failed ws/images/a.png: JPEG file is truncated second line\n");
  const auto back = ReadViewRecord(path);
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->failure, "ws/images/a.png: JPEG file is truncated second line");
  EXPECT_EQ(back->seconds, 0);
  // "failed" without a reason is not a record.
  WriteFileBytes(path, "failed\n");
  EXPECT_FALSE(ReadViewRecord(path).has_value());
}

TEST(ViewRecordTest, AbsentOrDamagedRecordsReadAsNone) {
  TempDir dir;
  EXPECT_FALSE(ReadViewRecord(dir.path() / "missing.txt").has_value());
  const std::string good = "seconds 2\nsize 8x6\nsources 2\ndevice cpu\n";
  const fs::path path = dir.path() / "r.txt";
  WriteFileBytes(path, good);
  ASSERT_TRUE(ReadViewRecord(path).has_value());
  for (const std::string& bad :
       {std::string(), good.substr(0, 20), std::string("seconds nan\nsize 8x6\nsources 2\ndevice cpu\n"),
        std::string("seconds -1\nsize 8x6\nsources 2\ndevice cpu\n"),
        std::string("seconds 2\nsize 0x6\nsources 2\ndevice cpu\n"),
        std::string("seconds 2\nsize 8*6\nsources 2\ndevice cpu\n"),
        std::string("seconds 2\nsize 8x6\nsources -3\ndevice cpu\n"),
        std::string("seconds 2\nsize 8x6\nsources 2\ndevice\n"), std::string("\xff\xfe garbage")}) {
    WriteFileBytes(path, bad);
    EXPECT_FALSE(ReadViewRecord(path).has_value()) << bad;
  }
}

TEST(ViewRecordTest, RefusesNamesThatLeaveTheWorkspace) {
  TempDir dir;
  const Workspace workspace = MakeWorkspace(dir);
  EXPECT_THROW(ViewRecordPath(workspace, "../outside.jpg"), IoError);
  EXPECT_THROW(ViewRecordPath(workspace, "/abs.jpg"), IoError);
}

}  // namespace
}  // namespace dispmvs::colmap_io
