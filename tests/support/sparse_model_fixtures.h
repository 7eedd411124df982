#pragma once
// Builders and exact comparisons of COLMAP sparse models, shared by the
// colmap_io unit tests and the interop tests against the real `colmap`.
//
// The comparisons are bit for bit: both users need round trips that restore
// every double exactly (-0.0 stays -0.0, a NaN never compares equal by
// accident), so no tolerance is offered.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "colmap_io/sparse_model.h"

namespace dispmvs::testing {

// True when the two doubles have the same bit pattern.
bool SameBits(double a, double b);

// EXPECTs each of the n doubles to match bit for bit; failures name
// `what`[i] and both values.
void ExpectSameDoubles(const double* expected, const double* actual, size_t n,
                       const std::string& what);

// EXPECTs every field of every camera, image and point to match, doubles
// bit for bit (ids stored inside the records included). Uses ASSERT for size
// mismatches, so callers that must stop there wrap it in
// ASSERT_NO_FATAL_FAILURE.
void ExpectIdenticalModels(const colmap_io::SparseModel& expected,
                           const colmap_io::SparseModel& actual);

colmap_io::Camera MakeCamera(colmap_io::camera_t id, int model_id, uint64_t width, uint64_t height,
                             std::vector<double> params);

// An image without points2D.
colmap_io::Image MakeImage(colmap_io::image_t id, colmap_io::camera_t camera_id,
                           const std::string& name, const Eigen::Vector4d& qvec,
                           const Eigen::Vector3d& tvec);

}  // namespace dispmvs::testing
