#pragma once
// Per-image depth ranges from the sparse model, computed the way COLMAP's
// dense MVS does (colmap/mvs/model.cc, Model::ComputeDepthRanges): take the
// camera-frame depths of the sparse points an image observes, pick robust low
// and high percentiles and widen them by a margin.
//
// For DispMVS the range is only a HINT (random initialisation and loss
// normalisation, see docs/method.md, section 1 "The depth-range hint"):
// nothing is clipped to it. An image that sees too few points is therefore
// reported invalid instead of being given an invented range; the caller
// chooses a fallback, for instance FallbackDepthRange() below.

#include <cstddef>
#include <map>

#include "colmap_io/sparse_model.h"

namespace dispmvs::colmap_io {

struct DepthRangeOptions {
  // Percentiles as fractions in [0, 1]. As in COLMAP, the value taken is
  // sorted_depths[floor(n * percentile)] (clamped to the last element), so
  // for depths 1, 2, ..., 100 the defaults pick 2 and 100.
  double min_percentile = 0.01;
  double max_percentile = 0.99;
  // The range is widened to [(1 - s) * low, (1 + s) * high]; s in [0, 1).
  double stretch_ratio = 0.25;
  // Fewer usable depths than this make the image's range invalid. COLMAP
  // accepts a single point; raise this to distrust sparse images.
  std::size_t min_num_points = 1;

  // Throws std::invalid_argument naming the offending field.
  void Check() const;
};

struct DepthRange {
  double d_min = 0.0;
  double d_max = 0.0;
  // Number of usable depths the range was computed from (points in front of
  // the camera with a finite depth), also filled when the range is invalid.
  std::size_t num_points = 0;
  // False when fewer than min_num_points depths were usable; d_min and d_max
  // are then 0 and must not be used.
  bool valid = false;
};

// The range of one image. A depth is z = (R X + t).z of each point3D referenced
// by the image's points2D; points at z <= 0 (behind or on the camera plane),
// non-finite depths and point3D ids missing from the model are ignored. Each
// observation contributes one depth (a point observed twice counts twice, as
// with COLMAP's track-based loop). Throws std::invalid_argument when
// `image_id` is not in the model or the options fail Check().
DepthRange ComputeDepthRange(const SparseModel& model, image_t image_id,
                             const DepthRangeOptions& options = {});

// ComputeDepthRange for every image of the model, keyed by image id.
std::map<image_t, DepthRange> ComputeDepthRanges(const SparseModel& model,
                                                 const DepthRangeOptions& options = {});

// A fallback for images whose range is invalid: the union of all VALID ranges
// in `ranges` (smallest d_min, largest d_max; num_points is the sum). It is
// invalid when no range is valid, in which case the caller must ask the user
// for a range (or refuse): there is nothing in the model to derive one from.
// Why the union: the images of one reconstruction see the same scene, and a
// too-wide hint only costs DispMVS some accuracy while a too-narrow one can
// miss the surface in the initialisation.
DepthRange FallbackDepthRange(const std::map<image_t, DepthRange>& ranges);

}  // namespace dispmvs::colmap_io
