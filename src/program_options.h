#pragma once
// Boost.ProgramOptions as the project's programs use it: --help prints the
// options and wins over everything else, including missing required options.

#include <boost/program_options.hpp>

namespace dispmvs::cli {

// Parses argv into `values` and runs the notifiers. Returns false after
// printing `description` to standard output when --help was given (the
// caller exits with status 0). Throws what Boost throws for unknown options
// and malformed values (RunProgram turns it into the error line).
bool ParseCommandLine(int argc, char** argv,
                      const boost::program_options::options_description& description,
                      boost::program_options::variables_map* values);

}  // namespace dispmvs::cli
