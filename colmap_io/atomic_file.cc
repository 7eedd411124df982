#include "colmap_io/atomic_file.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <system_error>
#include <vector>

#include "colmap_io/error.h"

namespace dispmvs::colmap_io {
namespace {

// What a temporary name adds to the final one, before "PID-N";
// RemoveLeftoverTemporaries finds the temporaries by it.
constexpr const char* kTemporaryMark = ".tmp-";

// Unique within the process (counter) and across processes (pid), so two
// writers of the same file never share a temporary name.
std::filesystem::path TemporaryNameFor(const std::filesystem::path& path) {
  static std::atomic<unsigned long> counter{0};
  return path.string() + kTemporaryMark + std::to_string(::getpid()) + "-" +
         std::to_string(counter++);
}

}  // namespace

AtomicFileWriter::AtomicFileWriter(const std::filesystem::path& path)
    : path_(path), temp_path_(TemporaryNameFor(path)) {
  std::error_code ec;
  if (path_.has_parent_path()) {
    std::filesystem::create_directories(path_.parent_path(), ec);
    if (ec) throw IoError(path_.string(), "cannot create directory: " + ec.message());
  }
  stream_.open(temp_path_, std::ios::binary | std::ios::trunc);
  if (!stream_) throw IoError(path_.string(), "cannot open for writing");
}

AtomicFileWriter::~AtomicFileWriter() {
  if (!committed_) {
    stream_.close();
    std::error_code ec;
    std::filesystem::remove(temp_path_, ec);
  }
}

void AtomicFileWriter::Commit() {
  stream_.flush();
  const bool ok = static_cast<bool>(stream_);
  stream_.close();
  if (!ok || stream_.fail()) throw IoError(path_.string(), "write failed (disk full?)");
  std::error_code ec;
  std::filesystem::rename(temp_path_, path_, ec);
  if (ec) throw IoError(path_.string(), "cannot rename temporary file into place: " + ec.message());
  committed_ = true;
}

void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write) {
  AtomicFileWriter writer(path);
  write(writer.stream());
  writer.Commit();
}

int RemoveLeftoverTemporaries(const std::filesystem::path& path) {
  const std::filesystem::path folder = path.has_parent_path() ? path.parent_path() : ".";
  const std::string prefix = path.filename().string() + kTemporaryMark;
  std::error_code ec;
  if (!std::filesystem::is_directory(folder, ec)) return 0;
  std::vector<std::filesystem::path> leftovers;
  std::filesystem::directory_iterator entries(folder, ec);
  if (ec) throw IoError(folder.string(), "cannot list: " + ec.message());
  for (const auto& entry : entries) {
    if (entry.path().filename().string().rfind(prefix, 0) == 0) leftovers.push_back(entry.path());
  }
  for (const std::filesystem::path& leftover : leftovers) {
    std::filesystem::remove(leftover, ec);
    if (ec) throw IoError(leftover.string(), "cannot remove a leftover temporary file: " + ec.message());
  }
  return static_cast<int>(leftovers.size());
}

std::vector<std::string> NamesWithTemporaries(const std::filesystem::path& folder) {
  std::error_code ec;
  if (!std::filesystem::is_directory(folder, ec)) return {};
  std::filesystem::directory_iterator entries(folder, ec);
  if (ec) throw IoError(folder.string(), "cannot list: " + ec.message());
  std::vector<std::string> names;
  for (const auto& entry : entries) {
    const std::string file = entry.path().filename().string();
    const std::size_t mark = file.rfind(kTemporaryMark);
    if (mark != std::string::npos && mark > 0) names.push_back(file.substr(0, mark));
  }
  std::sort(names.begin(), names.end());
  names.erase(std::unique(names.begin(), names.end()), names.end());
  return names;
}

}  // namespace dispmvs::colmap_io
