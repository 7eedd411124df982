#pragma once
// Multi-view geometric-consistency filtering of depth maps: a reference depth
// is kept only where enough source views, whose own depth maps see the same
// 3-D point, agree with it (forward-backward reprojection, as COLMAP's
// geometric stage and most learned-MVS pipelines do).
//
// Conventions (COLMAP's dense stage): the depth at (row, col) is the camera z
// of X_cam = depth * K^-1 (col, row, 1)^T with raw integer pixel indices; a
// world point X projects to x = K (R X + t), (col, row) = (x0/x2, x1/x2); R, t
// are world-to-camera. K is the intrinsics of the depth map's own resolution.
// Depths that are not finite and > 0 are "no depth" everywhere.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "colmap_io/dense_array.h"

namespace dispmvs::fusion {

// Sources one reference can be checked against: the per-pixel result is a
// 32-bit mask with one bit per source.
constexpr int kMaxSourceViews = 32;
// The largest GeometricFilterOptions::support_radius.
constexpr int kMaxSupportRadius = 32;

// The defaults are COLMAP's rule (1 px, 1 %, two sources, no support), which
// dispmvs_colmap's fusion keeps; its geometric pass takes
// SupportFilterDefaults().
struct GeometricFilterOptions {
  // Distance in reference pixels between a reference pixel and its
  // forward-backward reprojection through a source depth map.
  double max_reprojection_error = 1.0;
  // |d_reproj - d_ref| / d_ref, with d_reproj the reference-camera depth of
  // the back-projected source point.
  double max_relative_depth_error = 0.01;
  // Sources that must agree for a reference depth to be kept, 0..32 (0 keeps
  // every valid depth).
  int min_consistent_views = 2;
  // Pixels (reference and source) whose confidence is below this count as
  // "no depth" where the view has a confidence map.
  double min_confidence = 0;
  // Spatial support, 0 = off (COLMAP's rule): a pixel that passes the test
  // above is kept only where at least this share of the pixels of the
  // (2 support_radius + 1)^2 window around it (those inside the image, the
  // pixel itself included) pass it too. A wrong depth agrees with a source
  // by accident at scattered pixels, a right one over whole patches of a
  // surface: the support drops the first and lets the thresholds above be
  // looser for the second (docs/dense.md, "The geometric filter").
  double min_support = 0;
  int support_radius = 2;

  // Throws std::invalid_argument naming the first bad field: thresholds must
  // be finite and >= 0, min_consistent_views in [0, kMaxSourceViews],
  // min_confidence finite, min_support in [0, 1], support_radius in
  // [1, kMaxSupportRadius].
  void Check() const;
};

// The geometric pass's rule in dispmvs_colmap: 2 px, 2 %, two sources, and
// 60 % of the 5x5 window around a pixel passing too. Against COLMAP's rule
// (the struct's defaults) on the validation photographs (realval's two-view
// pairs) its maps keep more of the right pixels at a higher precision (all
// ground-truth pixels kept and within 2 %: 0.536 against 0.505; kept pixels
// within 2 %: 0.939 against 0.934), and on generated six-view scenes more at
// a lower precision (0.329 against 0.265; 0.892 against 0.920;
// docs/dense.md, "The geometric filter"). Fusion keeps COLMAP's rule: with
// the support its clouds of those scenes lost recall (F-score 0.764 against
// 0.780).
GeometricFilterOptions SupportFilterDefaults();

// One view as the filter sees it.
struct DepthView {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  // at the depth map's resolution
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world-to-camera rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // world-to-camera translation
  colmap_io::DenseArray depth;                      // 1 channel, 0 = no depth
  colmap_io::DenseArray confidence;                 // 1 channel, same size, or empty
};

struct GeometricFilterResult {
  // The reference depth where at least min_consistent_views sources agree
  // (and, with min_support > 0, enough of the pixels around too), else 0
  // (never NaN or negative).
  colmap_io::DenseArray depth;
  // Per pixel, row-major (index row * width + col): bit i set when
  // sources[i] agrees. Computed for every pixel with a usable reference
  // depth, kept or not; 0 elsewhere.
  std::vector<uint32_t> consistent_mask;
  // Per pixel, row-major: the number of bits set in consistent_mask.
  std::vector<uint8_t> num_consistent;
  // Pixels kept in `depth`.
  std::size_t num_kept = 0;
};

// Checks every reference pixel with a usable depth against every source:
// back-project to the world, project into the source; if that lands inside
// the source map, read the source depth at the nearest pixel (rounded),
// back-project that source pixel and project it back into the reference. The
// source agrees if the reprojection lands within max_reprojection_error of
// (col, row) AND its reference-camera depth is within
// max_relative_depth_error of the reference depth. A pixel passes where at
// least min_consistent_views sources agree; with min_support > 0 it is kept
// where the share of passing pixels in its support window reaches
// min_support.
//
// Throws std::invalid_argument for invalid options, more than
// kMaxSourceViews sources, a null source, an empty or multi-channel depth
// map, a confidence map of another size, or a bad K / R / t.
GeometricFilterResult FilterDepthMap(const DepthView& reference,
                                     const std::vector<const DepthView*>& sources,
                                     const GeometricFilterOptions& options);

// The forward-backward check of one (reference, source) pair with the
// geometry precomputed, shared by FilterDepthMap and FusePoints. Check() does
// no allocation. The views must outlive this object and have passed
// ValidateDepthView.
class PairConsistency {
 public:
  PairConsistency(const DepthView& reference, const DepthView& source,
                  const GeometricFilterOptions& options);

  // The source pixel a successful Check read, and its depth there.
  struct Match {
    int row = 0;
    int col = 0;
    float depth = 0.0f;
  };

  // Whether the source agrees with reference pixel (row, col) at depth
  // `reference_depth` (> 0); fills `match` when it does.
  bool Check(int row, int col, double reference_depth, Match* match) const;

 private:
  const DepthView& source_;
  double max_reprojection_error_squared_;
  double max_relative_depth_error_;
  double min_confidence_;
  // Reference pixel (col, row, 1) * depth -> source homogeneous pixel:
  // forward_ * depth * (col, row, 1) + forward_offset_.
  Eigen::Matrix3d forward_;
  Eigen::Vector3d forward_offset_;
  // Same from the source back into the reference.
  Eigen::Matrix3d backward_;
  Eigen::Vector3d backward_offset_;
};

// Throws std::invalid_argument (message starting with `what`) unless `view`
// has a non-empty 1-channel depth map, an empty or same-size 1-channel
// confidence map, a finite invertible K with last row (0, 0, 1), a rotation R
// and a finite t.
void ValidateDepthView(const DepthView& view, const std::string& what);

// Whether (row, col) of `view` holds a depth the filter uses: valid and, where
// the view has a confidence map, confidence >= min_confidence.
bool HasUsableDepth(const DepthView& view, int row, int col, double min_confidence);

}  // namespace dispmvs::fusion
