#pragma once
// One point of a fused cloud: what COLMAP's fused.ply stores per vertex plus
// the fused.ply.vis entry (the images that see it). Kept apart from
// point_fusion.h so that the file writers need neither OpenCV nor the fusion
// code.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

namespace dispmvs::fusion {

struct FusedPoint {
  Eigen::Vector3f xyz = Eigen::Vector3f::Zero();     // world frame
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  // world frame, unit or 0 if unknown
  std::array<uint8_t, 3> rgb = {0, 0, 0};
  // Image indices (FusionView::vis_index) of the views the point was fused
  // from, sorted ascending, no duplicates.
  std::vector<uint32_t> visibility;
};

}  // namespace dispmvs::fusion
