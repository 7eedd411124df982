#pragma once
// The region of space fusion keeps points in: an axis-aligned box in world
// coordinates, read from COLMAP's bounding-box file (`colmap stereo_fusion
// --bbox_path`): six numbers separated by white space, the minimum corner
// x y z, then the maximum corner x y z.

#include <Eigen/Core>
#include <filesystem>

namespace dispmvs::fusion {

struct BoundingBox {
  Eigen::Vector3d min = Eigen::Vector3d::Zero();
  Eigen::Vector3d max = Eigen::Vector3d::Zero();

  // Inclusive on every face, as COLMAP's test (a point on a face is inside).
  bool Contains(const Eigen::Vector3d& point) const {
    return (point.array() >= min.array()).all() && (point.array() <= max.array()).all();
  }
};

// Reads COLMAP's format. Stricter than COLMAP, which continues without a box
// when the file cannot be opened and takes whatever a short or malformed file
// leaves in the corners: throws colmap_io::IoError (naming the file) unless
// it holds exactly six finite numbers with min <= max on every axis.
BoundingBox ReadBoundingBox(const std::filesystem::path& path);

}  // namespace dispmvs::fusion
