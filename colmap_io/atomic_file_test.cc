#include "colmap_io/atomic_file.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::TempDir;
using dispmvs::testing::WriteFileBytes;

// Names of every entry directly inside `dir`, to catch leftover temporaries.
std::vector<std::string> ListDirectory(const std::filesystem::path& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    names.push_back(entry.path().filename().string());
  }
  return names;
}

TEST(AtomicFileTest, WritesContentAndLeavesNoTemporary) {
  TempDir dir;
  const auto path = dir.path() / "out.txt";
  WriteFileAtomically(path, [](std::ostream& out) { out << "hello\n" << 42; });
  EXPECT_EQ(ReadFileBytes(path), "hello\n42");
  EXPECT_EQ(ListDirectory(dir.path()), std::vector<std::string>{"out.txt"});
}

TEST(AtomicFileTest, CreatesParentDirectories) {
  TempDir dir;
  const auto path = dir.path() / "a" / "b" / "c.bin";
  WriteFileAtomically(path, [](std::ostream& out) { out.write("\0\1", 2); });
  EXPECT_EQ(ReadFileBytes(path), std::string("\0\1", 2));
}

TEST(AtomicFileTest, ReplacesExistingFile) {
  TempDir dir;
  const auto path = dir.path() / "out.txt";
  WriteFileBytes(path, "old content that is longer");
  WriteFileAtomically(path, [](std::ostream& out) { out << "new"; });
  EXPECT_EQ(ReadFileBytes(path), "new");
}

TEST(AtomicFileTest, ExceptionWhileWritingKeepsOldFileAndRemovesTemporary) {
  TempDir dir;
  const auto path = dir.path() / "out.txt";
  WriteFileBytes(path, "old");
  EXPECT_THROW(WriteFileAtomically(path,
                                   [](std::ostream& out) {
                                     out << "partial";
                                     throw std::runtime_error("interrupted");
                                   }),
               std::runtime_error);
  EXPECT_EQ(ReadFileBytes(path), "old");
  EXPECT_EQ(ListDirectory(dir.path()), std::vector<std::string>{"out.txt"});
}

TEST(AtomicFileTest, WriterWithoutCommitLeavesNothing) {
  TempDir dir;
  const auto path = dir.path() / "never.txt";
  {
    AtomicFileWriter writer(path);
    writer.stream() << "data";
    EXPECT_EQ(writer.path(), path);
  }
  EXPECT_TRUE(ListDirectory(dir.path()).empty());
}

TEST(AtomicFileTest, ContentIsInvisibleUntilCommit) {
  TempDir dir;
  const auto path = dir.path() / "late.txt";
  AtomicFileWriter writer(path);
  writer.stream() << "data";
  writer.stream().flush();
  EXPECT_FALSE(std::filesystem::exists(path));
  writer.Commit();
  EXPECT_EQ(ReadFileBytes(path), "data");
}

TEST(AtomicFileTest, ParentThatIsAFileIsAnIoErrorNamingThePath) {
  TempDir dir;
  WriteFileBytes(dir.path() / "plain", "x");
  const auto path = dir.path() / "plain" / "child.txt";
  try {
    AtomicFileWriter writer(path);
    FAIL() << "expected IoError";
  } catch (const IoError& error) {
    EXPECT_EQ(error.path(), path.string());
  }
}

TEST(AtomicFileTest, FailedRenameIsAnIoErrorAndRemovesTemporary) {
  TempDir dir;
  // A non-empty directory under the final name: rename(2) cannot replace it.
  const auto path = dir.path() / "occupied";
  WriteFileBytes(path / "inside.txt", "x");
  EXPECT_THROW(WriteFileAtomically(path, [](std::ostream& out) { out << "data"; }), IoError);
  EXPECT_EQ(ListDirectory(dir.path()), std::vector<std::string>{"occupied"});
  EXPECT_TRUE(std::filesystem::is_directory(path));
}

TEST(AtomicFileTest, RemoveLeftoverTemporariesTakesOnlyThatFilesTemporaries) {
  TempDir dir;
  const auto path = dir.path() / "out.bin";
  WriteFileBytes(path, "complete");
  WriteFileBytes(dir.path() / "out.bin.tmp-4242-0", "killed writer");
  WriteFileBytes(dir.path() / "out.bin.tmp-77-13", "another killed writer");
  // Other files' temporaries and look-alikes stay.
  WriteFileBytes(dir.path() / "out.bin.vis.tmp-4242-1", "x");
  WriteFileBytes(dir.path() / "out.bin2.tmp-1-0", "x");
  WriteFileBytes(dir.path() / "xout.bin.tmp-1-0", "x");
  EXPECT_EQ(RemoveLeftoverTemporaries(path), 2);
  std::vector<std::string> left = ListDirectory(dir.path());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{"out.bin", "out.bin.vis.tmp-4242-1", "out.bin2.tmp-1-0",
                                            "xout.bin.tmp-1-0"}));
  EXPECT_EQ(ReadFileBytes(path), "complete");
  EXPECT_EQ(RemoveLeftoverTemporaries(path), 0);
  EXPECT_EQ(RemoveLeftoverTemporaries(dir.path() / "missing" / "out.bin"), 0);
}

TEST(AtomicFileTest, NamesWithTemporariesListsEachOutputOnce) {
  TempDir dir;
  WriteFileBytes(dir.path() / "a.txt", "complete, no temporary");
  WriteFileBytes(dir.path() / "b.txt.tmp-4242-0", "x");
  WriteFileBytes(dir.path() / "b.txt.tmp-77-13", "x");
  WriteFileBytes(dir.path() / "c.bin.vis.tmp-1-0", "x");
  WriteFileBytes(dir.path() / "plain.tmp", "not a temporary name");
  EXPECT_EQ(NamesWithTemporaries(dir.path()), (std::vector<std::string>{"b.txt", "c.bin.vis"}));
  EXPECT_EQ(RemoveLeftoverTemporaries(dir.path() / "b.txt"), 2);
  EXPECT_EQ(NamesWithTemporaries(dir.path()), (std::vector<std::string>{"c.bin.vis"}));
  EXPECT_TRUE(NamesWithTemporaries(dir.path() / "missing").empty());
}

TEST(AtomicFileTest, RemoveLeftoverTemporariesFindsTheWritersOwnNames) {
  // The names it removes are the ones AtomicFileWriter makes: here a live
  // writer's, which is why only a caller that excludes other writers may
  // call it (the writer's Commit then fails instead of writing).
  TempDir dir;
  const auto path = dir.path() / "late.txt";
  AtomicFileWriter writer(path);
  writer.stream() << "data";
  writer.stream().flush();
  EXPECT_EQ(RemoveLeftoverTemporaries(path), 1);
  EXPECT_TRUE(ListDirectory(dir.path()).empty());
  EXPECT_THROW(writer.Commit(), IoError);
  EXPECT_FALSE(std::filesystem::exists(path));
}

}  // namespace
}  // namespace dispmvs::colmap_io
