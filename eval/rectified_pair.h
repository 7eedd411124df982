#pragma once
// Rectified stereo pairs in a sparse model, for the disparity metrics of
// depth_metrics.h.
//
// Two registered images form a rectified pair when, within the tolerances
// below:
//   * both cameras are PINHOLE or SIMPLE_PINHOLE,
//   * their world-to-camera rotations are equal (every matrix entry),
//   * the camera centres differ along the (shared) camera x-axis only: with
//     B = |C_b - C_a| > 0 and v = R (C_b - C_a) in camera coordinates,
//     |v_y| and |v_z| are below the tolerance times B,
//   * fx, fy and cy are equal (cx may differ: that is the pair's doffs).
// Epipolar lines are then image rows, and depth z maps to disparity
// f_x B / z + doffs. Image sizes do not matter.

#include <optional>
#include <string>

#include "colmap_io/sparse_model.h"

namespace dispmvs::eval {

// Largest difference of any rotation-matrix entry.
constexpr double kRectifiedRotationTolerance = 1e-9;
// Largest y or z component of the centre difference, relative to the baseline.
constexpr double kRectifiedOffAxisTolerance = 1e-9;
// Largest relative difference of fx, fy and cy (relative to the larger
// magnitude): equal up to the rounding of a text model.
constexpr double kRectifiedIntrinsicsTolerance = 1e-9;

// The baseline B (in the model's units) when (camera_a, image_a) and
// (camera_b, image_b) form a rectified pair as defined above, else nullopt.
// Symmetric in a and b.
std::optional<double> RectifiedBaseline(const colmap_io::Camera& camera_a,
                                        const colmap_io::Image& image_a,
                                        const colmap_io::Camera& camera_b,
                                        const colmap_io::Image& image_b);

struct RectifiedPartner {
  colmap_io::image_t image_id = 0;
  std::string name;
  double baseline = 0;
};

// The image of `model` that forms a rectified pair with `image_id`; with
// several, the one with the shortest baseline (baselines equal within
// kRectifiedIntrinsicsTolerance relative are a tie, which the smallest name
// wins), so that the choice does not depend on image ids. nullopt when there is none.
// Throws std::out_of_range when `image_id` or a camera is not in the model.
std::optional<RectifiedPartner> FindRectifiedPartner(const colmap_io::SparseModel& model,
                                                     colmap_io::image_t image_id);

}  // namespace dispmvs::eval
