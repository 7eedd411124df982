#pragma once
// COLMAP's fused.ply.vis: for every point of fused.ply, in the same order, the
// images that see it (COLMAP's Poisson and Delaunay meshers read it). Layout,
// little endian:
//
//   uint64 number of points
//   per point: uint32 count, then count x uint32 image index
//
// The image index is the position of the image in the fusion's list of
// images, which is what FusionView::vis_index holds.

#include <cstdint>
#include <filesystem>
#include <istream>
#include <string>
#include <vector>

#include "fusion/fused_point.h"

namespace dispmvs::fusion {

// Pieces of the layout above, appended to `out`: the point count, and one
// point's list (at most 2^32 - 1 images; the caller checks), for writers
// that stream points (fused_cloud_writer.h).
void AppendVisibilityHeader(uint64_t num_points, std::string* out);
void AppendVisibilityRecord(const std::vector<uint32_t>& images, std::string* out);

// Writes the visibility lists of `points` atomically (colmap_io/atomic_file.h),
// creating parent directories. Throws colmap_io::IoError naming `path`.
void WriteVisibilityFile(const std::vector<FusedPoint>& points,
                         const std::filesystem::path& path);

// Reads a .vis file back, one list per point. Throws colmap_io::IoError naming
// the path (or `source_name`) when it cannot be opened, is truncated, declares
// counts the remaining bytes cannot hold (checked before allocating) or has
// trailing bytes.
std::vector<std::vector<uint32_t>> ReadVisibilityFile(const std::filesystem::path& path);
std::vector<std::vector<uint32_t>> ReadVisibilityFile(std::istream& in,
                                                      const std::string& source_name);

// Writes `ply_path` (colmap_io::WritePlyPoints) and `ply_path` + ".vis", each
// atomically; the .vis first, so that a fused.ply from this call never sits
// beside a .vis from an older run. Non-finite normals are written as 0.
void WriteFusedPointCloud(const std::vector<FusedPoint>& points,
                          const std::filesystem::path& ply_path);

}  // namespace dispmvs::fusion
