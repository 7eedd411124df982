#pragma once
// Normal maps from depth maps, for views whose depth estimator produces no
// normals (the network estimates depth only, while COLMAP's fusion and
// meshers want a normal per point).
//
// Conventions (COLMAP's dense stage): the depth at (row, col) is the camera z
// of X_cam = depth * K^-1 (col, row, 1)^T, with raw integer pixel indices;
// depth 0 (or anything not finite and positive) means "no depth". The normal
// map has 3 channels (x, y, z in the CAMERA frame), unit length, oriented
// towards the camera (n . X_cam < 0), and 0 where unknown.

#include <Eigen/Core>

#include "colmap_io/dense_array.h"

namespace dispmvs::fusion {

// Relative depth difference between a pixel and a 4-neighbour above which
// the two are taken to lie on different surfaces (an occlusion edge).
constexpr double kDefaultMaxRelativeDepthJump = 0.05;

// Per pixel with a valid depth: back-projects the 4-neighbours and takes the
// normal as the cross product of the horizontal and vertical differences
// (central where both neighbours along an axis have depth, one-sided where
// only one has). The normal is 0 where an axis has no neighbour with depth,
// or where any neighbour with depth differs from the pixel's depth by more
// than `max_relative_depth_jump` (relative to the pixel's depth): such a
// normal would straddle an occlusion edge. On a plane the result is exact up
// to float rounding.
//
// `K` is the intrinsics of the depth map's own resolution (last row 0 0 1).
// Throws std::invalid_argument if `depth` is empty or not 1-channel, if K is
// not finite and invertible with last row (0, 0, 1), or if
// max_relative_depth_jump is not finite and positive.
colmap_io::DenseArray NormalMapFromDepth(
    const colmap_io::DenseArray& depth, const Eigen::Matrix3d& K,
    double max_relative_depth_jump = kDefaultMaxRelativeDepthJump);

}  // namespace dispmvs::fusion
