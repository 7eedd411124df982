#pragma once
// The passes of dispmvs_colmap over a planned workspace:
//   photometric: DispMVS per reference image -> depth, normal, confidence maps
//                (NAME.dispmvs.photometric.bin);
//   geometric:   multi-view geometric-consistency filtering of those maps
//                (NAME.dispmvs.geometric.bin);
//   fusion:      consistent pixels averaged into fused.ply + fused.ply.vis;
//   export:      the maps under COLMAP's PatchMatch names in a sibling
//                workspace, for Debian's `colmap stereo_fusion`, which only
//                accepts --input_type photometric|geometric.
// Every file is written to a temporary name and renamed. A view whose
// outputs all exist is skipped unless `overwrite`; a view that fails is
// reported and the others go on.

#include <cstdint>
#include <filesystem>
#include <ostream>
#include <string>
#include <vector>

#include "colmap_io/workspace.h"
#include "fusion/geometric_filter.h"
#include "src/dense_plan.h"
#include "src/depth_estimator.h"

namespace dispmvs::dense {

inline constexpr const char* kPhotometricType = "dispmvs.photometric";
inline constexpr const char* kGeometricType = "dispmvs.geometric";

struct PassSummary {
  int done = 0;
  int skipped_existing = 0;
  int skipped_no_sources = 0;
  std::vector<std::string> failures;  // "NAME: why"
  double seconds = 0;
};

struct PhotometricOptions {
  EstimatorOptions estimator;
  // COLMAP's max_image_size: images whose larger side exceeds it are
  // downscaled (maps are written at that size, as PatchMatch does); <= 0 =
  // full size.
  int max_image_size = -1;
  uint64_t seed = 0;
  bool overwrite = false;
  void Check() const;  // throws std::invalid_argument naming the option
};

// Runs the network on every problem of the plan with at least one source.
// Progress lines (per view time, ETA) go to `log`.
PassSummary RunPhotometricPass(const colmap_io::Workspace& workspace, const DensePlan& plan,
                               const PhotometricOptions& options, std::ostream& log);

// Filters the photometric maps of every problem of the plan against the
// photometric maps of its sources (those that exist) and writes the
// geometric maps (depth, normal, confidence; 0 where inconsistent). A
// reference in plan.min_consistent_views needs that many agreeing sources
// instead of options.min_consistent_views (RunFusion alike).
// Always recomputed: it is cheap and depends on the neighbours' maps.
PassSummary RunGeometricPass(const colmap_io::Workspace& workspace, const DensePlan& plan,
                             const fusion::GeometricFilterOptions& options, std::ostream& log);

struct FusionSummary {
  std::size_t num_points = 0;
  int num_images = 0;
  double seconds = 0;
};

// Fuses the photometric maps of the images listed in stereo/fusion.cfg (or of
// every problem's reference, without it) that have maps, with the same
// consistency rule (plan.min_consistent_views included), into `ply_path` and
// `ply_path`.vis.
FusionSummary RunFusion(const colmap_io::Workspace& workspace, const DensePlan& plan,
                        const fusion::GeometricFilterOptions& options,
                        const std::filesystem::path& ply_path, std::ostream& log);

// Writes a workspace at `export_root` whose images/ and sparse/ link to
// ours (symbolic links) and whose stereo/ holds our photometric and geometric
// maps under COLMAP's names (NAME.photometric.bin, NAME.geometric.bin) plus
// our patch-match.cfg and fusion.cfg. Returns the number of images exported.
int ExportForColmap(const colmap_io::Workspace& workspace, const DensePlan& plan,
                    const std::filesystem::path& export_root, std::ostream& log);

}  // namespace dispmvs::dense
