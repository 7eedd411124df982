#pragma once
// Helpers shared by the libFuzzer targets whose readers or writers only take
// paths: a scratch directory per fuzzing process (under $TMPDIR, removed at
// exit) and whole-file byte I/O. Header-only, standard library only.

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <system_error>

#include <unistd.h>

namespace dispmvs::fuzz {

// The scratch directory of this process. libFuzzer's -fork/-jobs modes run
// several processes, so the name carries the process id. The path is never
// destroyed, so that the exit handler removing the directory can still use it.
inline const std::filesystem::path& ScratchDir() {
  static const std::filesystem::path* const dir = [] {
    const auto* path = new std::filesystem::path(std::filesystem::temp_directory_path() /
                                                 ("dispmvs-fuzz-" + std::to_string(::getpid())));
    std::filesystem::create_directories(*path);
    std::atexit([] {
      std::error_code ignored;
      std::filesystem::remove_all(ScratchDir(), ignored);
    });
    return path;
  }();
  return *dir;
}

inline std::filesystem::path ScratchPath(const std::string& name) { return ScratchDir() / name; }

// Aborts (a reported crash) on I/O failure: the harness, not the reader under
// test, is broken then.
inline void WriteBytes(const std::filesystem::path& path, const uint8_t* data, size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) std::abort();
}

inline std::string ReadBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) std::abort();
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

}  // namespace dispmvs::fuzz
