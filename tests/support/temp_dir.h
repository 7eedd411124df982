#pragma once
// A fresh, uniquely named directory under the system temp dir, removed with
// everything in it when the object goes out of scope.

#include <filesystem>
#include <string>

namespace dispmvs::testing {

class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  // path() / relative, with parent directories created.
  std::filesystem::path Make(const std::string& relative) const;

 private:
  std::filesystem::path path_;
};

// Writes `bytes` to `path` (creating parent directories).
void WriteFileBytes(const std::filesystem::path& path, const std::string& bytes);
std::string ReadFileBytes(const std::filesystem::path& path);

}  // namespace dispmvs::testing
