#pragma once
// Fusion of filtered depth maps into one point cloud (the step COLMAP's
// stereo_fusion does): every reference pixel that enough of its source views
// agree with becomes one point, the mean of its own 3-D point and the agreeing
// source points; the source pixels used are consumed so that the same surface
// patch is not emitted again when that source is the reference.
//
// Pixel and pose conventions are those of geometric_filter.h.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include "colmap_io/dense_array.h"
#include "fusion/bounding_box.h"
#include "fusion/fused_point.h"
#include "fusion/geometric_filter.h"

namespace dispmvs::fusion {

struct FusionView {
  DepthView geometry;
  // 3 channels, unit normals in the CAMERA frame (0 = unknown), same size as
  // the depth map; or empty (no normals: points get the mean of the normals
  // the other views have, or 0).
  colmap_io::DenseArray normals;
  // CV_32FC3 RGB in [0, 1] or CV_8UC3 RGB, at the depth map's size; or empty
  // (no colour: points get the mean colour of the other views, or black).
  cv::Mat image;
  // The image index written into fused.ply.vis for this view.
  uint32_t vis_index = 0;
  // Indices into the same vector of FusionView, at most kMaxSourceViews,
  // without duplicates and without the view itself.
  std::vector<int> source_views;
  // Agreeing sources this view needs as a reference, in [0, kMaxSourceViews];
  // -1 = options.min_consistent_views. A view with fewer sources than the
  // options ask (one map in a stereo pair) can be given what it has, so that
  // it is not silently empty.
  int min_consistent_views = -1;
};

// What fusion does beyond the consistency rule: COLMAP's StereoFusion options
// that mean something for fusion of this kind (docs/colmap-options.md). The
// defaults here change nothing (a fusion of the consistency rule alone);
// dispmvs_colmap sets its own.
struct FusionOptions {
  GeometricFilterOptions consistency;
  // Degrees: an agreeing source pixel is fused only if its world normal lies
  // within this angle of the reference pixel's (where both have one), as
  // COLMAP tests each pixel against the first of a point. 180 = no test.
  double max_normal_error = 180;
  // Pixels averaged into one point at most: the reference's, then agreeing
  // sources in list order. Agreeing sources past it still count towards
  // min_consistent_views but are neither averaged nor consumed (COLMAP stops
  // its traversal there and leaves them for later points too).
  int max_num_pixels = 10000;
  // COLMAP's traversal depth: 1 keeps every point at its reference pixel
  // alone (agreement is still required); 2 or more is this fusion, which
  // never goes beyond a reference's direct sources.
  int max_traversal_depth = 100;
  // Sources each reference is checked against at most: the first N of its
  // list (the plan lists the most overlapping first).
  int check_num_images = 50;
  // Pixels whose 3-D point lies outside are used for nothing: no point at a
  // reference pixel outside, and a source pixel outside does not agree.
  std::optional<BoundingBox> bounding_box;

  FusionOptions() = default;
  // Implicit on purpose: the consistency rule alone is a complete request.
  FusionOptions(const GeometricFilterOptions& rule) : consistency(rule) {}  // NOLINT

  // Throws std::invalid_argument naming the first bad field (as
  // GeometricFilterOptions::Check, and: max_normal_error in [0, 180],
  // max_num_pixels >= 1 and >= min_consistent_views + 1 (a point needs the
  // pixels it must agree with), max_traversal_depth and check_num_images
  // >= 1, box corners finite with min <= max).
  void Check() const;
};

// What FusePoints did, per view (same order as the views).
struct FusionStats {
  // Points emitted with the view as the reference.
  std::vector<std::size_t> points_per_view;
  // Pixels with a usable depth skipped because an earlier reference consumed
  // them.
  std::vector<std::size_t> consumed_pixels_per_view;
};

// Visits the views in order and, within a view, the pixels row by row. A
// reference pixel with a usable depth (geometric_filter.h) that no earlier
// reference consumed, and that at least min_consistent_views of its source
// views agree with (the view's own if set, else the options'; the test of
// FilterDepthMap), and, with the rule's min_support > 0, that FilterDepthMap
// keeps against the view's sources (dispmvs_colmap leaves it 0 in fusion),
// becomes one point:
//   xyz        mean of the reference point and the agreeing source points,
//              each source point being the source's own depth at the rounded
//              projection, back-projected;
//   normal     normalised mean of the world-frame normals (R^T n) of those
//              pixels that have one; 0 if none has;
//   rgb        mean colour of those pixels whose view has an image;
//   visibility sorted unique vis_index of the reference and agreeing sources.
// The agreeing source pixels are marked consumed. Consumed pixels still serve
// as sources (agreement and averaging); they are only never references.
// FusionOptions adds COLMAP's tests on top: the bounding box, the normal
// angle, the most pixels per point and the sources checked.
//
// Throws std::invalid_argument for invalid options or views (bad geometry,
// maps of the wrong size or channel count, an image of another type or size,
// source indices out of range, repeated, pointing at the view itself or more
// than kMaxSourceViews, a min_consistent_views outside [-1, kMaxSourceViews]).
std::vector<FusedPoint> FusePoints(const std::vector<FusionView>& views,
                                   const FusionOptions& options,
                                   FusionStats* stats = nullptr);

class FusionViewCache;  // fusion/view_cache.h

// The same, with views 0 .. num_views - 1 taken from `cache` when needed (a
// reference and its sources at a time), so that the maps held at once stay
// within the cache's budget whatever the number of views; only one byte per
// pixel of every view (what has been consumed) is kept throughout. A view
// the cache cannot load is left out, as a reference and as a source. Each
// view is checked as above when first loaded. Gives the points of the
// vector form for the same usable views.
std::vector<FusedPoint> FusePoints(int num_views, FusionViewCache* cache,
                                   const FusionOptions& options,
                                   FusionStats* stats = nullptr);

// The same, each point handed to `emit` as soon as it is made, in the same
// order, instead of collected (fusion/fused_cloud_writer.h writes them out),
// so that memory does not grow with the number of points either.
// `last_use`, if not empty, gives for each view the last reference (view
// index) that uses it, as itself or as a source (LastUses below): the view's
// one byte per pixel is then freed after that reference, and memory does not
// grow with the number of views at all. A view asked for after its last use
// is a std::logic_error.
using PointSink = std::function<void(FusedPoint&&)>;
void FusePoints(int num_views, FusionViewCache* cache, const FusionOptions& options,
                const PointSink& emit, FusionStats* stats = nullptr,
                const std::vector<int>& last_use = {});

// last_use for FusePoints: sources[v] lists the source views of view v.
std::vector<int> LastUses(const std::vector<std::vector<int>>& sources);

}  // namespace dispmvs::fusion
