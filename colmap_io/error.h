#pragma once
// The one exception type colmap_io throws for bad input. Its message always
// names the file (or directory) at fault, so a command-line program can print
// it as is and exit non-zero.

#include <stdexcept>
#include <string>

namespace dispmvs::colmap_io {

class IoError : public std::runtime_error {
 public:
  IoError(const std::string& path, const std::string& what)
      : std::runtime_error(path + ": " + what), path_(path) {}
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

}  // namespace dispmvs::colmap_io
