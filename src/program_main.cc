#include "src/program_main.h"

#include <exception>
#include <iostream>
#include <string>

namespace dispmvs::cli {

int RunProgram(const std::function<int()>& body) {
  try {
    return body();
  } catch (const std::exception& error) {
    std::string message = error.what();
    for (char& c : message) {
      if (c == '\n' || c == '\r') c = ' ';
    }
    std::cerr << "error: " << message << '\n';
  } catch (...) {
    std::cerr << "error: unknown exception\n";
  }
  return 1;
}

}  // namespace dispmvs::cli
