#pragma once
// Source-view selection for a reference image, reproducing COLMAP's
// `__auto__, N` entry of patch-match.cfg (colmap/mvs/model.cc,
// Model::GetMaxOverlappingImages): among the other images, keep those whose
// triangulation angle with the reference reaches a minimum, then take the N
// sharing the most sparse points with it.
//
// Triangulation angle of a pair: for every shared point X, the angle between
// the rays from the two camera centres to X, folded to min(a, pi - a) (as
// COLMAP's CalculateTriangulationAngle does); the pair's angle is the given
// percentile of these (COLMAP: 75th, picked as sorted[round(p/100 * (n-1))]).
// A pair with identical centres therefore has angle 0 and is rejected.

#include <cstddef>
#include <vector>

#include "colmap_io/sparse_model.h"

namespace dispmvs::colmap_io {

struct ViewSelectionOptions {
  // COLMAP's PatchMatchOptions::min_triangulation_angle default, in degrees;
  // pairs whose angle is below it are excluded. In [0, 90].
  double min_triangulation_angle_deg = 1.0;
  // Percentile (in [0, 100]) of the per-point angles used as the pair's angle.
  double triangulation_angle_percentile = 75.0;

  // Throws std::invalid_argument naming the offending field.
  void Check() const;
};

struct SourceViewCandidate {
  image_t image_id = 0;
  std::size_t num_shared_points = 0;
  double triangulation_angle_deg = 0.0;
};

// Every other image sharing at least one sparse point with the reference and
// passing the angle test, sorted by num_shared_points (descending), ties by
// image_id (ascending) so the order never depends on container order.
// Shared points are found through the reference's points2D and the tracks of
// their points3D; a point counts once per pair even if observed twice, and
// track elements naming images absent from the model are ignored.
// Throws std::invalid_argument when the reference is not in the model or the
// options fail Check(). An image observing no points gives an empty list.
std::vector<SourceViewCandidate> RankSourceViews(const SparseModel& model,
                                                 image_t reference_image_id,
                                                 const ViewSelectionOptions& options = {});

// The first `max_num_source_views` images of RankSourceViews (fewer if fewer
// qualify): what `__auto__, max_num_source_views` means in patch-match.cfg.
std::vector<image_t> SelectSourceViews(const SparseModel& model,
                                       image_t reference_image_id,
                                       std::size_t max_num_source_views,
                                       const ViewSelectionOptions& options = {});

}  // namespace dispmvs::colmap_io
