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
#include <vector>

#include "colmap_io/dense_array.h"
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
// FilterDepthMap), becomes one point:
//   xyz        mean of the reference point and the agreeing source points,
//              each source point being the source's own depth at the rounded
//              projection, back-projected;
//   normal     normalised mean of the world-frame normals (R^T n) of those
//              pixels that have one; 0 if none has;
//   rgb        mean colour of those pixels whose view has an image;
//   visibility sorted unique vis_index of the reference and agreeing sources.
// The agreeing source pixels are marked consumed. Consumed pixels still serve
// as sources (agreement and averaging); they are only never references.
//
// Throws std::invalid_argument for invalid options or views (bad geometry,
// maps of the wrong size or channel count, an image of another type or size,
// source indices out of range, repeated, pointing at the view itself or more
// than kMaxSourceViews, a min_consistent_views outside [-1, kMaxSourceViews]).
std::vector<FusedPoint> FusePoints(const std::vector<FusionView>& views,
                                   const GeometricFilterOptions& options,
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
                                   const GeometricFilterOptions& options,
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
void FusePoints(int num_views, FusionViewCache* cache, const GeometricFilterOptions& options,
                const PointSink& emit, FusionStats* stats = nullptr,
                const std::vector<int>& last_use = {});

// last_use for FusePoints: sources[v] lists the source views of view v.
std::vector<int> LastUses(const std::vector<std::vector<int>>& sources);

}  // namespace dispmvs::fusion
