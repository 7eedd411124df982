#pragma once
// Running a command-line program in a test and checking how it failed: the
// shared helpers of the programs' CLI tests.

#include <string>

#include "tests/support/temp_dir.h"

namespace dispmvs::testing {

struct ProgramRun {
  int status = -1;  // exit status; -1 when the program did not exit normally
  std::string out, err;
};

// Runs `program` with `args` (a shell-quoted argument string) through the
// shell, its standard output and error captured in files of `scratch`.
ProgramRun RunProgram(const TempDir& scratch, const std::string& program, const std::string& args);

// The projects' error convention: exit status 1 and exactly one line on
// standard error, "error: ...", containing `fragment`.
void ExpectError(const ProgramRun& run, const std::string& fragment);

}  // namespace dispmvs::testing
