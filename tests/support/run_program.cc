#include "tests/support/run_program.h"

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>

namespace dispmvs::testing {

ProgramRun RunProgram(const TempDir& scratch, const std::string& program, const std::string& args) {
  const std::filesystem::path out = scratch.path() / "stdout.txt";
  const std::filesystem::path err = scratch.path() / "stderr.txt";
  const std::string command =
      "'" + program + "' " + args + " >'" + out.string() + "' 2>'" + err.string() + "'";
  const int raw = std::system(command.c_str());
  ProgramRun run;
  run.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  run.out = ReadFileBytes(out);
  run.err = ReadFileBytes(err);
  return run;
}

void ExpectError(const ProgramRun& run, const std::string& fragment) {
  EXPECT_EQ(run.status, 1) << run.out << run.err;
  EXPECT_EQ(run.err.rfind("error: ", 0), 0u) << run.err;
  ASSERT_FALSE(run.err.empty());
  EXPECT_EQ(run.err.find('\n'), run.err.size() - 1) << run.err;
  EXPECT_NE(run.err.find(fragment), std::string::npos) << run.err;
}

}  // namespace dispmvs::testing
