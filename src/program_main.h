#pragma once
// What every command-line program of the project does around its work, in
// one place: the error convention (one line "error: MESSAGE" on standard
// error, exit status 1; never an uncaught exception) and --help.

#include <functional>

namespace dispmvs::cli {

// Runs `body` and returns its exit status; an exception becomes the error
// line (line breaks in the message turned into spaces, so that it stays one
// line) and status 1.
int RunProgram(const std::function<int()>& body);

}  // namespace dispmvs::cli
