// Per-view claims: exclusive between open files (so between processes),
// released on destruction and when the holding process dies, and the
// holder's pid reported to whoever finds the view taken.

#include "dense/view_claim.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <optional>

#include <gtest/gtest.h>

#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::dense {
namespace {

namespace fs = std::filesystem;
using ::dispmvs::testing::TempDir;

TEST(ViewClaimTest, OneHolderAtATimeAndTheOthersLearnWho) {
  TempDir dir;
  const fs::path lock = dir.path() / "claims" / "sub" / "a.png.lock";  // folders made
  std::optional<ViewClaim> first = ViewClaim::TryClaim(lock);
  ASSERT_TRUE(first.has_value());
  long holder = -1;
  EXPECT_FALSE(ViewClaim::TryClaim(lock, &holder).has_value());
  EXPECT_EQ(holder, ::getpid());
  // Another view is independent.
  EXPECT_TRUE(ViewClaim::TryClaim(dir.path() / "claims" / "b.png.lock").has_value());

  ViewClaim moved = std::move(*first);  // moving keeps the claim
  first.reset();
  EXPECT_FALSE(ViewClaim::TryClaim(lock).has_value());
  { ViewClaim released = std::move(moved); }
  EXPECT_TRUE(ViewClaim::TryClaim(lock).has_value());
}

TEST(ViewClaimTest, AKilledHolderLeavesNoClaim) {
  TempDir dir;
  const fs::path lock = dir.path() / "v.lock";
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {  // claim, tell the parent, wait to be killed
    ::close(ready[0]);
    std::optional<ViewClaim> claim = ViewClaim::TryClaim(lock);
    const char byte = claim ? 1 : 0;
    if (::write(ready[1], &byte, 1) != 1) ::_exit(2);
    for (;;) ::pause();
  }
  ::close(ready[1]);
  char byte = 0;
  ASSERT_EQ(::read(ready[0], &byte, 1), 1);
  ::close(ready[0]);
  ASSERT_EQ(byte, 1);
  long holder = 0;
  EXPECT_FALSE(ViewClaim::TryClaim(lock, &holder).has_value());
  EXPECT_EQ(holder, child);
  ::kill(child, SIGKILL);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFSIGNALED(status));
  EXPECT_TRUE(ViewClaim::TryClaim(lock).has_value());
}

TEST(ViewClaimTest, AnUnusableLockFolderIsAnIoError) {
  TempDir dir;
  const fs::path file = dir.path() / "not_a_folder";
  ::dispmvs::testing::WriteFileBytes(file, "x");
  EXPECT_THROW(ViewClaim::TryClaim(file / "v.lock"), colmap_io::IoError);
}

}  // namespace
}  // namespace dispmvs::dense
