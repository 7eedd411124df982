#pragma once
// Two dense methods compared on a workspace without ground truth: what a user
// weighing dispmvs against `colmap patch_match_stereo` on their own data can
// measure. For depth-map types A and B (e.g. dispmvs.geometric, geometric),
// per view and pooled over all pixels:
//   coverage     pixels with a valid depth (finite, > 0) / pixels, each type
//   shared       pixels where both have one
//   agreement    shared pixels whose depths lie within 1 / 2 / 5 % of each
//                other: 2 |a - b| / (a + b) < X %, symmetric in A and B
//   consistency  each type on its own: of its valid pixels in views with at
//                least one source map of the same type, those that at least
//                `min_consistent_views` of those source maps agree with
//                (fusion/geometric_filter.h: forward-backward reprojection
//                within max_reprojection_error pixels and relative depth
//                within max_relative_depth_error), the test fusion applies
// Sources are patch-match.cfg's (or `__auto__, 4` without it), resolved with
// the sparse model as COLMAP does, and, as dispmvs_colmap does, from the
// camera poses for an `__auto__` reference that shares no sparse point (a
// workspace without sparse points still gets consistency figures). Maps of
// different sizes (max_image_size) are compared at the smaller size, the
// larger sampled at the nearest pixel in COLMAP's dense convention
// (eval/depth_metrics.h); the sizes must be a clean scale of one another.
//
// Point clouds A and B (e.g. our fused.ply and stereo_fusion's) are compared
// as eval/cloud_metrics.h compares a reconstruction with ground truth, B
// standing in for the ground truth: accuracy = mean distance A -> B,
// completeness = B -> A, precision / recall / F-score at tau; tau and the
// cut-off default to fractions of B's bounding-box diagonal.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "colmap_io/stereo_config.h"
#include "eval/cloud_metrics.h"
#include "fusion/geometric_filter.h"

namespace dispmvs::eval {

struct MethodComparisonOptions {
  std::string type_a, type_b;
  // The consistency test; min_consistent_views 1 by default (a pixel that
  // one other view confirms).
  fusion::GeometricFilterOptions consistency = DefaultConsistency();
  // Clouds (both or neither).
  std::string ply_a, ply_b;
  double tau_relative = 0.002, cutoff_relative = 0.02;  // of B's diagonal
  // `__auto__, N` sources are capped at this many, as dispmvs_colmap's
  // --max_num_src_images caps them (same default), so that the maps are
  // checked against the sources the run used.
  int max_num_src_images = colmap_io::kDefaultMaxNumSourceImages;

  static fusion::GeometricFilterOptions DefaultConsistency();
  void Check() const;  // std::invalid_argument naming the problem
};

// Pixel counts; they add over views.
struct AgreementSums {
  int64_t pixels = 0;  // at the compared size
  int64_t valid_a = 0, valid_b = 0, shared = 0;
  int64_t within_1 = 0, within_2 = 0, within_5 = 0;  // of the shared pixels
  // Valid pixels of views with a source map of the same type, and of those
  // the consistent ones.
  int64_t checked_a = 0, consistent_a = 0, checked_b = 0, consistent_b = 0;

  AgreementSums& operator+=(const AgreementSums& other);
};

// Fractions of AgreementSums; NaN where the denominator is 0.
struct Agreement {
  double coverage_a = 0, coverage_b = 0, shared = 0;
  double within_1 = 0, within_2 = 0, within_5 = 0;  // of the shared pixels
  double consistency_a = 0, consistency_b = 0;
};
Agreement Fractions(const AgreementSums& sums);

struct ViewComparison {
  std::string name;
  bool has_a = false, has_b = false;  // compared only when both are there
  int width = 0, height = 0;          // the compared size
  int sources_a = 0, sources_b = 0;   // source maps used for consistency
  AgreementSums sums;
};

struct CloudComparison {
  std::string ply_a, ply_b;
  int64_t nonfinite_dropped_a = 0, nonfinite_dropped_b = 0;
  CloudMetrics a_against_b;  // B as the reference
};

struct MethodComparison {
  std::string workspace, type_a, type_b;
  std::vector<ViewComparison> views;  // every registered image, by name
  int views_compared = 0;
  AgreementSums pooled;
  std::optional<CloudComparison> clouds;
};

// Throws IoError (naming the file) for unreadable inputs, and
// std::invalid_argument when neither type has any map or the options are bad.
MethodComparison CompareMethods(const std::filesystem::path& workspace_path,
                                const MethodComparisonOptions& options);

}  // namespace dispmvs::eval
