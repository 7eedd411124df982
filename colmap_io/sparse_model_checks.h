#pragma once
// Private to colmap_io's sparse-model readers: the per-record checks that the
// binary and the text reader share, so both reject exactly the same records.
// Each returns an empty string when the record is fine, otherwise what is
// wrong with it; the caller adds the file name, record index/line and id.

#include <string>

#include "colmap_io/sparse_model.h"

namespace dispmvs::colmap_io::internal {

// Known model, parameter count matching the model, finite parameters,
// non-zero size.
std::string CheckCamera(const Camera& camera);
// Finite pose, a quaternion that can be normalised (finite, not ~zero),
// finite 2-D coordinates.
std::string CheckImage(const Image& image);
// Finite position and error.
std::string CheckPoint3D(const Point3D& point);

}  // namespace dispmvs::colmap_io::internal
