#pragma once
// Where a depth map's errors lie: every ground-truth (GT) pixel of a view
// gets labels from the ground truth alone, and the depth metrics are split by
// them (dispmvs_eval --regions).
//
// Visibility, from the other views' GT depth maps and poses: the pixel's GT
// point is
//   seen     inside another view with GT, whose GT surface there is not
//            nearer than the point by more than kHiddenDepthTolerance
//            (relative; a hole in that GT, no surface, counts as seen:
//            nothing says it is hidden); in at least one such view
//   hidden   inside some other view, but behind a nearer surface in all of
//            them: no source can match it
//   outside  inside no other view (or no other view has GT)
// A point projects to image position (u, v) = K (R X + t) / z in COLMAP's
// dense convention (the one fusion uses: pixel (col, row) of a map at image
// scale is position (col, row), no half-pixel shift; a map scaled by s is
// position (col / s, row / s)); it is inside a view of W x H when z > 0 and
// -0.5 <= u < W - 0.5, -0.5 <= v < H - 0.5, and it reads that view's GT at the
// nearest GT pixel. A single source decides everything in a two-view pair;
// with more, "seen" by any of them.
//
// Depth edges: two 4-neighbouring GT pixels, both with a surface, whose
// depths differ by more than kEdgeLogDepthStep in log depth (about 5 %) both
// lie on an edge. A seen pixel's distance to the nearest such pixel, in GT
// pixels along rows and columns (L1; 0 on an edge), puts it in one of the
// rings of kEdgeRings. Near an edge a window straddles two surfaces.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/sparse_model.h"
#include "eval/depth_metrics.h"

namespace dispmvs::eval {

constexpr double kHiddenDepthTolerance = 0.03;
constexpr double kEdgeLogDepthStep = 0.05;

// Rings of distance to the nearest depth edge: [0, 1], [2, 3], [4, 6],
// [7, 12], 13 and more (GT pixels).
constexpr std::array<int, 4> kEdgeRingUpper{1, 3, 6, 12};
constexpr int kNumEdgeRings = static_cast<int>(kEdgeRingUpper.size()) + 1;

enum class Visibility : uint8_t { kSeen = 0, kHidden = 1, kOutside = 2 };
constexpr int kNumVisibilities = 3;

// The per-pixel labels of one view, at its GT map's size (CV_8UC1):
// visibility (a Visibility) and the ring of the distance to the nearest depth
// edge (0 .. kNumEdgeRings - 1). Pixels without a GT surface are 255 in both.
struct RegionLabels {
  cv::Mat visibility, edge_ring;
};

// Another view: its GT depth map (at its camera's size or a clean down-scale
// of it), camera and pose.
struct OtherView {
  const colmap_io::DenseArray* gt = nullptr;
  const colmap_io::Camera* camera = nullptr;
  const colmap_io::Image* image = nullptr;
};

// Visibility labels of `gt` (the view's GT depth, a clean down-scale of its
// camera or at its size) against `others`. Throws std::invalid_argument for
// maps that are not one channel or not a clean scale of their camera.
cv::Mat LabelVisibility(const colmap_io::DenseArray& gt, const colmap_io::Camera& camera,
                        const colmap_io::Image& image, const std::vector<OtherView>& others);

// The L1 distance of every GT pixel with a surface to the nearest depth-edge
// pixel (CV_32SC1; a large value where the map has no edge, -1 where no GT
// surface).
cv::Mat DistanceToDepthEdge(const colmap_io::DenseArray& gt);

// The ring of kEdgeRingUpper a distance falls in.
int EdgeRing(int distance);

RegionLabels LabelRegions(const colmap_io::DenseArray& gt, const colmap_io::Camera& camera,
                          const colmap_io::Image& image, const std::vector<OtherView>& others);

// Per class: GT pixels (at the map's size) and those within 1 / 2 / 5 %.
struct RegionClassSums {
  int64_t gt_pixels = 0, within_1 = 0, within_2 = 0, within_5 = 0;
  RegionClassSums& operator+=(const RegionClassSums& other);
};

struct ErrorRegionSums {
  std::array<RegionClassSums, kNumVisibilities> visibility{};
  // Seen pixels only, by their distance to the nearest depth edge.
  std::array<RegionClassSums, kNumEdgeRings> seen_by_edge_ring{};
  int64_t gt_pixels = 0;  // all classes
  ErrorRegionSums& operator+=(const ErrorRegionSums& other);
};

// The rows a report prints, in order: a name and the class's sums.
std::vector<std::pair<std::string, RegionClassSums>> RegionRows(const ErrorRegionSums& sums);

// Splits one map's relative errors (`rel_error`, the CV_32FC1 image
// SumDepthMetrics writes, at the map's size) by `labels` (at the GT's size;
// map pixels read the GT pixel NearestGtIndex gives, as the metrics do).
// Throws std::invalid_argument when the sizes do not fit.
ErrorRegionSums SumErrorRegions(const cv::Mat& rel_error, const RegionLabels& labels);

}  // namespace dispmvs::eval
