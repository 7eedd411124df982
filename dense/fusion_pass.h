#pragma once
// The fusion pass of dispmvs_colmap: the photometric maps of the images listed
// in stereo/fusion.cfg (or of every problem's reference, without it) that
// have maps, fused with the geometric pass's consistency rule into a point
// cloud (fusion/point_fusion.h) written as PLY plus COLMAP's .vis file.

#include <cstddef>
#include <filesystem>
#include <optional>
#include <ostream>
#include <vector>

#include "colmap_io/workspace.h"
#include "dense/image_masks.h"
#include "dense/plan.h"
#include "dense/view_claim.h"
#include "fusion/point_fusion.h"

namespace dispmvs::dense {

struct FusionSummary {
  std::size_t num_points = 0;
  int num_images = 0;  // with usable maps
  std::size_t map_loads = 0;  // reads of a view's maps and image (>= num_images)
  std::size_t peak_cache_bytes = 0;
  // Pixels of the usable images, and how many of them their masks ignore.
  std::size_t pixels = 0;
  std::size_t masked_pixels = 0;
  double seconds = 0;
};

// Maps held at once by fusion unless one reference and its sources need more.
inline constexpr std::size_t kDefaultFusionCacheBytes = std::size_t{1024} * 1024 * 1024;

// The images fusion visits, in order: those of WS/stereo/fusion.cfg, else
// every reference of the plan. Throws IoError when fusion.cfg cannot be read
// or names an image that is not in the model (checked before any pass runs).
std::vector<colmap_io::image_t> FusionImageOrder(const colmap_io::Workspace& workspace,
                                                 const DensePlan& plan);

// Takes the workspace's fusion claim (FusionClaimPath) for the geometric
// pass and fusion that follow, then removes what killed runs left beside
// their outputs: the geometric maps' temporaries (RemoveGeometricLeftovers),
// those of `ply_path` (FusedCloudWriter::RemoveLeftovers) and those of
// `other_outputs` (files the run writes under the claim, e.g. its report),
// with a line in `log` when there were any. nullopt, with nothing removed,
// when another process holds the claim; `holder_pid` (optional) then
// receives its pid, 0 if unknown. Throws IoError when the lock or a
// leftover cannot be handled.
std::optional<ViewClaim> ClaimGeometricAndFusion(
    const colmap_io::Workspace& workspace, const DensePlan& plan,
    const std::filesystem::path& ply_path, const std::vector<std::filesystem::path>& other_outputs,
    std::ostream& log, long* holder_pid = nullptr);

// Writes `ply_path` and `ply_path`.vis (each through a temporary name). An
// image whose maps cannot be read is left out with a line in `log`; a
// fusion.cfg naming an image that is not in the model throws IoError.
// plan.min_consistent_views applies as in RunGeometricPass. Maps are read
// when needed and at most `max_cache_bytes` of them kept
// (fusion/view_cache.h), so memory does not grow with the number of images
// (beyond one byte per pixel per image). Pixels `masks` ignore are as if
// they had no depth (image_masks.h).
FusionSummary RunFusion(const colmap_io::Workspace& workspace, const DensePlan& plan,
                        const fusion::FusionOptions& options,
                        const std::filesystem::path& ply_path, std::ostream& log,
                        std::size_t max_cache_bytes = kDefaultFusionCacheBytes,
                        const ImageMasks& masks = {});

}  // namespace dispmvs::dense
