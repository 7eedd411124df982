#pragma once
// Accuracy of a reconstructed point cloud against a ground-truth (GT) cloud,
// with exact nearest neighbours from nanoflann k-d trees.
//
//   accuracy     = mean distance from each reconstructed point to its nearest
//                  GT point, ignoring distances >= cutoff (DTU style: those
//                  are outliers, counted in accuracy_cut)
//   completeness = mean distance from each GT point to its nearest
//                  reconstructed point, ignoring distances >= cutoff
//                  (counted in completeness_cut)
//   overall      = (accuracy + completeness) / 2
//   precision    = fraction of reconstructed points closer than tau to the GT
//   recall       = fraction of GT points closer than tau to the reconstruction
//   fscore       = 2 precision recall / (precision + recall), 0 when both are 0
// (Tanks-and-Temples style for the last three; all points count, cut or not).
// Means over no points are NaN; precision is NaN for an empty reconstruction
// (its fscore is 0); an empty GT cloud is an error.

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model.h"

namespace dispmvs::eval {

using PointCloud = std::vector<Eigen::Vector3f>;

// A 3-D k-d tree over a copy of `points` (which must all be finite). Exact
// (not approximate) nearest-neighbour queries; distances are evaluated in
// double precision.
class NearestNeighbourIndex {
 public:
  explicit NearestNeighbourIndex(PointCloud points);
  ~NearestNeighbourIndex();
  NearestNeighbourIndex(const NearestNeighbourIndex&) = delete;
  NearestNeighbourIndex& operator=(const NearestNeighbourIndex&) = delete;

  const PointCloud& points() const;
  std::size_t size() const { return points().size(); }
  // Euclidean distance from `query` to the nearest point; +inf when empty.
  double NearestDistance(const Eigen::Vector3d& query) const;
  // NearestDistance of every point of `queries`, in order.
  std::vector<double> NearestDistances(const PointCloud& queries) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct CloudMetricOptions {
  double tau = 0;     // precision / recall threshold, scene units, > 0
  double cutoff = 0;  // outlier cut-off of accuracy / completeness, > 0
  void Check() const;  // std::invalid_argument unless both are finite and > 0
};

struct CloudMetrics {
  int64_t num_points = 0;     // reconstructed points
  int64_t num_gt_points = 0;
  double tau = 0, cutoff = 0;
  double accuracy = 0, completeness = 0, overall = 0;
  int64_t accuracy_cut = 0;      // reconstructed points >= cutoff from the GT
  int64_t completeness_cut = 0;  // GT points >= cutoff from the reconstruction
  double precision = 0, recall = 0, fscore = 0;
};

// Both clouds given as built indices (so that a GT index serves several
// reconstructions). Throws std::invalid_argument when the GT is empty or the
// options are bad.
CloudMetrics EvaluateCloud(const NearestNeighbourIndex& reconstruction,
                           const NearestNeighbourIndex& gt, const CloudMetricOptions& options);

// Same, from the clouds from first principles (brute-force nearest neighbours,
// O(N M)): the reference the k-d tree version is tested against. Only for
// small clouds.
CloudMetrics EvaluateCloudBruteForce(const PointCloud& reconstruction, const PointCloud& gt,
                                     const CloudMetricOptions& options);

// Appends the finite points of `ply` to `cloud` (the k-d tree cannot hold
// the others); returns how many were dropped.
int64_t AppendFinitePoints(const std::vector<colmap_io::PlyPoint>& ply, PointCloud* cloud);

// Length of the diagonal of the axis-aligned bounding box; 0 when empty.
double BoundingBoxDiagonal(const PointCloud& points);

// World points of a depth map of `image` (camera `camera`, PINHOLE or
// SIMPLE_PINHOLE), every `stride`-th column and row starting at 0, skipping
// depths that are not finite and > 0, appended to `points`. COLMAP's dense
// convention (raw pixel indices, as stereo_fusion): the map may be a clean
// down-scale of the image (s_x = width / camera.width, s_y likewise), and
// pixel (col, row) with depth d is X_cam = d K^-1 (col / s_x, row / s_y, 1),
// X_world = R^T (X_cam - t) with (R, t) the image's world-to-camera pose.
// Throws std::invalid_argument for a non-pinhole camera, a map whose size is
// not a clean scale of the camera's, more than one channel, or stride < 1.
void BackProjectDepthMap(const colmap_io::DenseArray& depth, const colmap_io::Camera& camera,
                         const colmap_io::Image& image, int stride, PointCloud* points);

}  // namespace dispmvs::eval
