#pragma once
// Private to fusion/: argument checks shared by the public entry points. Each
// throws std::invalid_argument whose message starts with `what` (e.g.
// "FilterDepthMap: source view 2 K"), so a caller can tell which input is bad.

#include <Eigen/Core>
#include <limits>
#include <string>

#include "colmap_io/dense_array.h"

namespace dispmvs::fusion::internal {

// Finite, invertible, last row exactly (0, 0, 1): the projection code divides
// by the third homogeneous coordinate and takes it as the camera z.
void CheckIntrinsics(const Eigen::Matrix3d& K, const std::string& what);

// Finite and orthonormal with determinant +1 (to 1e-6): the code inverts it by
// transposing.
void CheckRotation(const Eigen::Matrix3d& R, const std::string& what);

void CheckFinite(const Eigen::Vector3d& v, const std::string& what);

// Non-empty and exactly `channels` channels.
void CheckMap(const colmap_io::DenseArray& map, int channels, const std::string& what);

// Same width and height as `like`.
void CheckSameSize(const colmap_io::DenseArray& map, const colmap_io::DenseArray& like,
                   const std::string& what);

// A depth the pipeline treats as present: finite and > 0 (0 is COLMAP's "no
// depth"; NaN, infinities and negative values are treated the same way).
// (NaN fails both comparisons.)
inline bool IsValidDepth(float depth) {
  return depth > 0.0f && depth <= std::numeric_limits<float>::max();
}

}  // namespace dispmvs::fusion::internal
