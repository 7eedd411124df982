#pragma once
// Crash-safe output: every file a user sees is either absent or complete.
// The content goes to a temporary name in the same directory, and only a
// successful Commit() renames it over the final name (rename is atomic on
// POSIX within one file system). An interrupted run leaves at most a
// "*.tmp-*" file behind, never a truncated output under the real name.

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

namespace dispmvs::colmap_io {

class AtomicFileWriter {
 public:
  // Creates the parent directory if needed. Throws IoError when the
  // temporary file cannot be opened.
  explicit AtomicFileWriter(const std::filesystem::path& path);
  // Removes the temporary file unless Commit() succeeded.
  ~AtomicFileWriter();
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

  std::ostream& stream() { return stream_; }
  const std::filesystem::path& path() const { return path_; }
  // Flushes, checks the stream, closes and renames into place; throws IoError
  // (naming the final path) if anything failed.
  void Commit();

 private:
  std::filesystem::path path_;
  std::filesystem::path temp_path_;
  std::ofstream stream_;
  bool committed_ = false;
};

// Convenience: WriteFileAtomically(path, [&](std::ostream& out) { ... });
void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write);

// Removes the temporary files that writers of `path` left beside it
// ("NAME.tmp-*" with NAME = path's file name; a killed process cannot clean
// up). Only for a caller that knows no other process is writing `path` now
// (e.g. one holding the path's per-view claim): a live writer's temporary
// would be deleted under it. Returns how many were removed; a missing folder
// is none. Throws IoError when the folder cannot be listed or a file removed.
int RemoveLeftoverTemporaries(const std::filesystem::path& path);

// The file names NAME in `folder` that have leftover temporaries beside them
// ("NAME.tmp-*"), each once, sorted: one listing to find which outputs
// RemoveLeftoverTemporaries has work for. A missing folder has none. Throws
// IoError when the folder cannot be listed.
std::vector<std::string> NamesWithTemporaries(const std::filesystem::path& folder);

}  // namespace dispmvs::colmap_io
