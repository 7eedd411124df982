#pragma once
// The fusion pass of dispmvs_colmap: the photometric maps of the images listed
// in stereo/fusion.cfg (or of every problem's reference, without it) that
// have maps, fused with the geometric pass's consistency rule into a point
// cloud (fusion/point_fusion.h) written as PLY plus COLMAP's .vis file.

#include <cstddef>
#include <filesystem>
#include <ostream>

#include "colmap_io/workspace.h"
#include "dense/plan.h"
#include "fusion/geometric_filter.h"

namespace dispmvs::dense {

struct FusionSummary {
  std::size_t num_points = 0;
  int num_images = 0;
  double seconds = 0;
};

// Writes `ply_path` and `ply_path`.vis (each through a temporary name). An
// image whose maps cannot be read is left out with a line in `log`; a
// fusion.cfg naming an image that is not in the model throws IoError.
// plan.min_consistent_views applies as in RunGeometricPass.
FusionSummary RunFusion(const colmap_io::Workspace& workspace, const DensePlan& plan,
                        const fusion::GeometricFilterOptions& options,
                        const std::filesystem::path& ply_path, std::ostream& log);

}  // namespace dispmvs::dense
