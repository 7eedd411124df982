#pragma once
// The photometric pass of dispmvs_colmap: the DispMVS network on every stereo
// problem of the plan that has at least one source, writing depth, normal and
// confidence maps of type dispmvs.photometric (dense/workspace_maps.h), and
// the view's time in WS/stereo/dispmvs_records/ (colmap_io/view_record.h).
// A view whose maps all exist is skipped unless `overwrite` (so a killed run
// resumes where it stopped); a view that fails is reported and the others
// go on. Each view is claimed (dense/view_claim.h) while it is computed; a
// view another process has claimed is skipped (PassSummary::skipped_claimed).

#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include "colmap_io/workspace.h"
#include "dense/depth_estimator.h"
#include "dense/pass_summary.h"
#include "dense/plan.h"

namespace dispmvs::dense {

struct PhotometricOptions {
  EstimatorOptions estimator;
  // COLMAP's max_image_size: images whose larger side exceeds it are
  // downscaled (maps are written at that size, as PatchMatch does); -1 =
  // full size.
  int max_image_size = -1;
  uint64_t seed = 0;
  bool overwrite = false;
  void Check() const;  // throws std::invalid_argument naming the option
};

// Progress lines (per view time, ETA) go to `log`. Weights that need a
// depth-range hint fail the whole pass before any view when some reference
// to compute has none (CheckHintsForWeights).
PassSummary RunPhotometricPass(const colmap_io::Workspace& workspace, const DensePlan& plan,
                               const PhotometricOptions& options, std::ostream& log);

// Removes the record temporaries (colmap_io/view_record.h) that a run killed
// between a view's maps and its record left beside the records of the
// `complete` views (their maps all exist, so no later run claims them to
// clear the rest), each under the view's claim: a view another process
// holds keeps its files. Returns how many files it removed. The photometric
// pass calls it on the views it skips as done.
int RemoveRecordLeftovers(const colmap_io::Workspace& workspace,
                          const std::vector<std::string>& complete);

// The seed of a view's random initialisation: a function of the run's seed
// and the image alone, so that results do not depend on order, sharding or
// resumption.
uint64_t ViewSeed(uint64_t seed, colmap_io::image_t image_id);

}  // namespace dispmvs::dense
