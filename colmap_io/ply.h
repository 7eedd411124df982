#pragma once
// Point clouds in the PLY layout of COLMAP's fused.ply (what stereo_fusion
// writes and the fusion/evaluation code reads): binary little endian, one
// "vertex" element with exactly these properties, in this order:
//
//   ply
//   format binary_little_endian 1.0
//   element vertex N
//   property float x        property float y        property float z
//   property float nx       property float ny       property float nz
//   property uchar red      property uchar green    property uchar blue
//   end_header
//
// (one property per line), followed by N records of 27 bytes.

#include <array>
#include <cstdint>
#include <filesystem>
#include <ostream>
#include <istream>
#include <string>
#include <vector>

namespace dispmvs::colmap_io {

struct PlyPoint {
  std::array<float, 3> xyz = {0, 0, 0};
  std::array<float, 3> normal = {0, 0, 0};
  std::array<uint8_t, 3> rgb = {0, 0, 0};

  bool operator==(const PlyPoint& other) const {
    return xyz == other.xyz && normal == other.normal && rgb == other.rgb;
  }
};

// Bytes of one record in the layout above.
constexpr std::size_t kPlyPointRecordBytes = 6 * 4 + 3;

// The header for `count` points, and one point's record, in the layout
// above: for writers that stream points (fusion/fused_cloud_writer.h).
void WritePlyHeader(uint64_t count, std::ostream& out);
void AppendPlyRecord(const PlyPoint& point, std::string* record);

// Writes atomically (atomic_file.h), creating parent directories; IoError
// naming `path` on failure. An empty cloud is a valid file (N = 0).
void WritePlyPoints(const std::vector<PlyPoint>& points, const std::filesystem::path& path);

// Reads a file in exactly the layout above; "comment" and "obj_info" header
// lines are skipped. Throws IoError naming `path` (or `source_name`) for any
// other format, element or property list, a vertex count the remaining bytes
// cannot hold (checked before allocating), or trailing bytes.
std::vector<PlyPoint> ReadPlyPoints(const std::filesystem::path& path);
std::vector<PlyPoint> ReadPlyPoints(std::istream& in, const std::string& source_name);

}  // namespace dispmvs::colmap_io
