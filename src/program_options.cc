#include "src/program_options.h"

#include <iostream>

namespace dispmvs::cli {

bool ParseCommandLine(int argc, char** argv,
                      const boost::program_options::options_description& description,
                      boost::program_options::variables_map* values) {
  namespace po = boost::program_options;
  po::store(po::parse_command_line(argc, argv, description), *values);
  if (values->count("help") > 0) {
    std::cout << description << '\n';
    return false;
  }
  po::notify(*values);
  return true;
}

}  // namespace dispmvs::cli
