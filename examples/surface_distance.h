#pragma once
// Distance of reconstructed points from the example scene's exact surfaces,
// for tests and demos that score a dense reconstruction of the example.

#include <vector>

#include <Eigen/Core>

#include "colmap_io/sparse_model.h"

namespace dispmvs::examples {

// For each point X, the distance from the surface along the ray from the
// camera of `model` that sees it best: |t - 1| * |X - C| for the first hit
// C + t (X - C) of the ray through X, minimised over the cameras (a point
// hidden from one view is seen by others); infinity when no ray from any
// camera through X hits the scene. Returned sorted ascending.
std::vector<double> SortedSurfaceDistances(const std::vector<Eigen::Vector3d>& points,
                                           const colmap_io::SparseModel& model);

}  // namespace dispmvs::examples
