#pragma once
// Writes fused.ply and fused.ply.vis point by point, so that fusion never
// holds its points in memory (18 million points of 2,000 images would take
// gigabytes): each point's PLY record and visibility list go to two body
// files beside the outputs as they come; Finish() writes each final file
// through a temporary name (atomic_file.h), header with the count first,
// then the body copied, and renames it into place, the .vis before the .ply
// as WriteFusedPointCloud does. The body files are removed in every case.
// Disk use is twice the cloud's size while Finish() runs.

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "fusion/fused_point.h"

namespace dispmvs::fusion {

class FusedCloudWriter {
 public:
  // Throws colmap_io::IoError naming the body file that cannot be created.
  explicit FusedCloudWriter(const std::filesystem::path& ply_path);
  ~FusedCloudWriter();
  FusedCloudWriter(const FusedCloudWriter&) = delete;
  FusedCloudWriter& operator=(const FusedCloudWriter&) = delete;

  // Non-finite normals are written as 0, as in WriteFusedPointCloud.
  void Add(const FusedPoint& point);
  uint64_t size() const { return count_; }
  // Writes both files; throws colmap_io::IoError naming the file that failed.
  void Finish();

  // Removes what killed writers of `ply_path` left: the body files and the
  // temporaries of both final files (colmap_io/atomic_file.h). Only for a
  // caller that knows no live process writes `ply_path` (dispmvs_colmap
  // holds the workspace's fusion claim, dense/view_claim.h). Returns how many
  // files were removed; throws colmap_io::IoError when one cannot be.
  static int RemoveLeftovers(const std::filesystem::path& ply_path);

 private:
  void Flush();

  std::filesystem::path ply_path_, vis_path_, ply_body_path_, vis_body_path_;
  std::ofstream ply_body_, vis_body_;
  std::string ply_buffer_, vis_buffer_;
  uint64_t count_ = 0;
};

}  // namespace dispmvs::fusion
