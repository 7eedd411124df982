#pragma once
// The geometric pass of dispmvs_colmap: filters the photometric map of every
// problem of the plan by multi-view geometric consistency against the
// photometric maps of its sources (those that exist; fusion/geometric_filter.h)
// and writes maps of type dispmvs.geometric (dense/workspace_maps.h): depth,
// normal and confidence, 0 where inconsistent.

#include <ostream>

#include "colmap_io/workspace.h"
#include "dense/image_masks.h"
#include "dense/pass_summary.h"
#include "dense/plan.h"
#include "fusion/geometric_filter.h"

namespace dispmvs::dense {

// A reference in plan.min_consistent_views needs that many agreeing sources
// instead of options.min_consistent_views. References without a photometric
// map count as skipped_no_sources; a reference whose own map cannot be read
// fails, and a source whose map cannot be read is left out (with a line in
// `log`) of the views that list it. Pixels `masks` ignore are neither kept
// nor agree as a source's. Always recomputed (no resume): it is cheap and
// depends on the neighbours' maps, which a later run may have added.
PassSummary RunGeometricPass(const colmap_io::Workspace& workspace, const DensePlan& plan,
                             const fusion::GeometricFilterOptions& options, std::ostream& log,
                             const ImageMasks& masks = {});

// Removes the temporaries (NAME.tmp-*, colmap_io/atomic_file.h) that a
// killed run left beside the geometric maps (depth, normal, confidence) of
// every image of the model, listing each map folder once. Only for a caller
// holding the fusion claim (FusionClaimPath, dense/view_claim.h): every
// writer of these maps holds it, so a temporary found then is a dead
// process's. Returns how many were removed; throws IoError when a folder
// cannot be listed or a file removed.
int RemoveGeometricLeftovers(const colmap_io::Workspace& workspace, const DensePlan& plan);

}  // namespace dispmvs::dense
