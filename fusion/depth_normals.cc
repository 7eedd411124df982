#include "fusion/depth_normals.h"

#include <Eigen/Dense>
#include <cmath>
#include <stdexcept>
#include <string>

#include "fusion/input_checks.h"

namespace dispmvs::fusion {
namespace {

using internal::IsValidDepth;

// One neighbour along an axis: present (has depth) or not; a present
// neighbour across a depth jump poisons the whole pixel.
enum class Neighbour { kAbsent, kPresent, kJump };

Neighbour Classify(float neighbour_depth, float depth, double max_jump) {
  if (!IsValidDepth(neighbour_depth)) return Neighbour::kAbsent;
  return std::abs(static_cast<double>(neighbour_depth) - depth) > max_jump * depth
             ? Neighbour::kJump
             : Neighbour::kPresent;
}

}  // namespace

colmap_io::DenseArray NormalMapFromDepth(const colmap_io::DenseArray& depth,
                                         const Eigen::Matrix3d& K,
                                         double max_relative_depth_jump) {
  internal::CheckMap(depth, 1, "NormalMapFromDepth: depth");
  internal::CheckIntrinsics(K, "NormalMapFromDepth");
  if (!std::isfinite(max_relative_depth_jump) || max_relative_depth_jump <= 0.0) {
    throw std::invalid_argument("NormalMapFromDepth: max_relative_depth_jump must be finite and > 0");
  }
  const int width = depth.width();
  const int height = depth.height();
  const std::size_t plane = static_cast<std::size_t>(width) * height;
  colmap_io::DenseArray normals(width, height, 3, 0.0f);
  const float* d = depth.data();
  float* n = normals.data();
  const Eigen::Matrix3d K_inv = K.inverse();

  // X_cam of pixel (row, col) at its depth (raw integer indices, COLMAP's
  // dense convention).
  auto back_project = [&](int row, int col) -> Eigen::Vector3d {
    const double z = d[static_cast<std::size_t>(row) * width + col];
    return z * (K_inv.col(0) * col + K_inv.col(1) * row + K_inv.col(2));
  };
  auto depth_at = [&](int row, int col) -> float {
    if (row < 0 || row >= height || col < 0 || col >= width) return 0.0f;
    return d[static_cast<std::size_t>(row) * width + col];
  };

  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const float z = d[static_cast<std::size_t>(row) * width + col];
      if (!IsValidDepth(z)) continue;
      const Neighbour left = Classify(depth_at(row, col - 1), z, max_relative_depth_jump);
      const Neighbour right = Classify(depth_at(row, col + 1), z, max_relative_depth_jump);
      const Neighbour up = Classify(depth_at(row - 1, col), z, max_relative_depth_jump);
      const Neighbour down = Classify(depth_at(row + 1, col), z, max_relative_depth_jump);
      if (left == Neighbour::kJump || right == Neighbour::kJump || up == Neighbour::kJump ||
          down == Neighbour::kJump) {
        continue;
      }
      const bool has_left = left == Neighbour::kPresent;
      const bool has_right = right == Neighbour::kPresent;
      const bool has_up = up == Neighbour::kPresent;
      const bool has_down = down == Neighbour::kPresent;
      if ((!has_left && !has_right) || (!has_up && !has_down)) continue;

      // Differences towards +col and +row; the central one spans two pixels,
      // which only scales the cross product.
      const Eigen::Vector3d dx = back_project(row, has_right ? col + 1 : col) -
                                 back_project(row, has_left ? col - 1 : col);
      const Eigen::Vector3d dy = back_project(has_down ? row + 1 : row, col) -
                                 back_project(has_up ? row - 1 : row, col);
      Eigen::Vector3d normal = dx.cross(dy);
      const double norm = normal.norm();
      if (!(norm > 0.0) || !std::isfinite(norm)) continue;
      normal /= norm;
      if (normal.dot(back_project(row, col)) > 0.0) normal = -normal;
      const std::size_t index = static_cast<std::size_t>(row) * width + col;
      for (int c = 0; c < 3; ++c) n[c * plane + index] = static_cast<float>(normal[c]);
    }
  }
  return normals;
}

}  // namespace dispmvs::fusion
