// libFuzzer target for the PLY point-cloud reader (fused.ply): the input is
// the whole file.
//
// Properties checked, besides "no crash, no sanitizer report, no huge
// allocation" (run with -rss_limit_mb):
//  * ReadPlyPoints throws nothing but IoError;
//  * an accepted file's body is exactly its points (27 bytes each, the last
//    bytes of the input);
//  * WritePlyPoints writes them, reading that file gives the same points bit
//    for bit, and writing them again gives the same bytes.

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "tests/fuzz/fuzz_support.h"

namespace {

using dispmvs::colmap_io::IoError;
using dispmvs::colmap_io::kPlyPointRecordBytes;
using dispmvs::colmap_io::PlyPoint;

// The record of `point` as the format stores it (little endian floats, which
// the x86-64 hosts the fuzzers run on use natively).
std::string Record(const PlyPoint& point) {
  std::string record(kPlyPointRecordBytes, '\0');
  std::memcpy(&record[0], point.xyz.data(), 12);
  std::memcpy(&record[12], point.normal.data(), 12);
  std::memcpy(&record[24], point.rgb.data(), 3);
  return record;
}

// Bitwise, so that NaN coordinates compare equal to themselves.
bool SameBits(const std::vector<PlyPoint>& a, const std::vector<PlyPoint>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (Record(a[i]) != Record(b[i])) return false;
  }
  return true;
}

std::vector<PlyPoint> ReadFromBytes(const std::string& bytes) {
  std::istringstream in(bytes);
  return dispmvs::colmap_io::ReadPlyPoints(in, "fuzz-input");
}

std::string WriteToBytes(const std::vector<PlyPoint>& points) {
  const auto path = dispmvs::fuzz::ScratchPath("points.ply");
  dispmvs::colmap_io::WritePlyPoints(points, path);
  return dispmvs::fuzz::ReadBytes(path);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  std::vector<PlyPoint> points;
  try {
    points = ReadFromBytes(input);
  } catch (const IoError&) {
    return 0;  // rejected cleanly: the expected outcome for most inputs
  }
  // The body is the input's tail: count records, nothing after them.
  std::string body;
  for (const PlyPoint& point : points) body += Record(point);
  if (body.size() > size || input.compare(size - body.size(), body.size(), body) != 0) {
    std::abort();
  }
  const std::string first = WriteToBytes(points);
  const std::vector<PlyPoint> again = ReadFromBytes(first);
  if (!SameBits(points, again) || WriteToBytes(again) != first) std::abort();
  return 0;
}
