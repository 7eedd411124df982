// libFuzzer target for the COLMAP dense array reader (depth, normal and
// confidence maps): the input is the whole file.
//
// Properties checked, besides "no crash, no sanitizer report, no huge
// allocation" (run with -rss_limit_mb):
//  * ReadDenseArray throws nothing but IoError;
//  * an accepted array has the dimensions its header gives, within the
//    documented limits, and exactly the payload's values;
//  * WriteDenseArray writes it, reading that file gives the same array bit for
//    bit, and writing it again gives the same bytes (a stable round trip).

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>

#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "tests/fuzz/fuzz_support.h"

namespace {

using dispmvs::colmap_io::DenseArray;
using dispmvs::colmap_io::IoError;

bool SameBits(const DenseArray& a, const DenseArray& b) {
  return a.width() == b.width() && a.height() == b.height() && a.channels() == b.channels() &&
         a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// Write `array` with the project's writer and return the file's bytes.
std::string WriteToBytes(const DenseArray& array) {
  const auto path = dispmvs::fuzz::ScratchPath("array.bin");
  dispmvs::colmap_io::WriteDenseArray(array, path);
  return dispmvs::fuzz::ReadBytes(path);
}

DenseArray ReadFromBytes(const std::string& bytes) {
  std::istringstream in(bytes);
  return dispmvs::colmap_io::ReadDenseArray(in, "fuzz-input");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  DenseArray array;
  try {
    array = ReadFromBytes(input);
  } catch (const IoError&) {
    return 0;  // rejected cleanly: the expected outcome for most inputs
  }
  // The reader refuses zero and oversized dimensions.
  if (array.empty() || array.width() <= 0 || array.height() <= 0 || array.channels() <= 0 ||
      static_cast<uint64_t>(array.width()) > dispmvs::colmap_io::kMaxDenseArraySide ||
      static_cast<uint64_t>(array.height()) > dispmvs::colmap_io::kMaxDenseArraySide ||
      static_cast<uint64_t>(array.channels()) > dispmvs::colmap_io::kMaxDenseArrayChannels) {
    std::abort();
  }
  // The payload is the tail of the input, exactly width*height*channels floats
  // (little endian, which the build host is: the fuzzers run on x86-64).
  const std::size_t payload = array.size() * sizeof(float);
  if (payload > size || std::memcmp(array.data(), data + size - payload, payload) != 0) {
    std::abort();
  }
  // Write(Read(Write(a))) == Write(a) and Read(Write(a)) == a, bit for bit.
  const std::string first = WriteToBytes(array);
  const DenseArray again = ReadFromBytes(first);
  if (!SameBits(array, again) || WriteToBytes(again) != first) std::abort();
  return 0;
}
