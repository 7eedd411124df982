#include "eval/cloud_metrics.h"

#include <nanoflann.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "eval/depth_metrics.h"

namespace dispmvs::eval {
namespace {

// nanoflann's dataset interface over a PointCloud. Coordinates are handed out
// as double so that differences (and the distances) are computed in double.
struct CloudAdaptor {
  const PointCloud* points = nullptr;

  std::size_t kdtree_get_point_count() const { return points->size(); }
  double kdtree_get_pt(uint32_t index, std::size_t dim) const {
    return static_cast<double>((*points)[index][static_cast<Eigen::Index>(dim)]);
  }
  template <class BoundingBox>
  bool kdtree_get_bbox(BoundingBox& /*unused*/) const {
    return false;  // let nanoflann compute it
  }
};

using KdTree = nanoflann::KDTreeSingleIndexAdaptor<
    nanoflann::L2_Simple_Adaptor<double, CloudAdaptor, double, uint32_t>, CloudAdaptor, 3,
    uint32_t>;

struct DistanceSummary {
  double mean_below_cutoff = 0;
  int64_t cut = 0;
  int64_t within_tau = 0;
};

DistanceSummary Summarise(const std::vector<double>& distances, const CloudMetricOptions& options) {
  DistanceSummary summary;
  double sum = 0;
  int64_t kept = 0;
  for (const double d : distances) {
    if (d < options.cutoff) {
      sum += d;
      ++kept;
    } else {
      ++summary.cut;
    }
    if (d < options.tau) ++summary.within_tau;
  }
  summary.mean_below_cutoff = kept > 0 ? sum / kept : std::numeric_limits<double>::quiet_NaN();
  return summary;
}

CloudMetrics Combine(const std::vector<double>& reconstruction_to_gt,
                     const std::vector<double>& gt_to_reconstruction,
                     const CloudMetricOptions& options) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  CloudMetrics m;
  m.num_points = static_cast<int64_t>(reconstruction_to_gt.size());
  m.num_gt_points = static_cast<int64_t>(gt_to_reconstruction.size());
  m.tau = options.tau;
  m.cutoff = options.cutoff;
  const DistanceSummary accuracy = Summarise(reconstruction_to_gt, options);
  const DistanceSummary completeness = Summarise(gt_to_reconstruction, options);
  m.accuracy = accuracy.mean_below_cutoff;
  m.accuracy_cut = accuracy.cut;
  m.completeness = completeness.mean_below_cutoff;
  m.completeness_cut = completeness.cut;
  m.overall = 0.5 * (m.accuracy + m.completeness);  // NaN if either is
  m.precision = m.num_points > 0 ? static_cast<double>(accuracy.within_tau) / m.num_points : nan;
  m.recall = static_cast<double>(completeness.within_tau) / m.num_gt_points;
  const double p = m.num_points > 0 ? m.precision : 0.0;
  m.fscore = p + m.recall > 0 ? 2 * p * m.recall / (p + m.recall) : 0.0;
  return m;
}

void CheckGt(std::size_t gt_size, const CloudMetricOptions& options) {
  options.Check();
  if (gt_size == 0) throw std::invalid_argument("the ground-truth point cloud is empty");
}

}  // namespace

struct NearestNeighbourIndex::Impl {
  PointCloud points;
  CloudAdaptor adaptor;
  std::unique_ptr<KdTree> tree;  // null when empty
};

NearestNeighbourIndex::NearestNeighbourIndex(PointCloud points) : impl_(std::make_unique<Impl>()) {
  if (points.size() >= static_cast<std::size_t>(std::numeric_limits<uint32_t>::max())) {
    throw std::invalid_argument("point cloud too large for the k-d tree (" +
                                std::to_string(points.size()) + " points)");
  }
  for (const Eigen::Vector3f& p : points) {
    if (!p.allFinite()) throw std::invalid_argument("point cloud holds a non-finite point");
  }
  impl_->points = std::move(points);
  impl_->adaptor.points = &impl_->points;
  if (!impl_->points.empty()) {
    impl_->tree = std::make_unique<KdTree>(3, impl_->adaptor,
                                           nanoflann::KDTreeSingleIndexAdaptorParams(10));
  }
}

NearestNeighbourIndex::~NearestNeighbourIndex() = default;

const PointCloud& NearestNeighbourIndex::points() const { return impl_->points; }

double NearestNeighbourIndex::NearestDistance(const Eigen::Vector3d& query) const {
  if (!impl_->tree) return std::numeric_limits<double>::infinity();
  uint32_t index = 0;
  double squared = std::numeric_limits<double>::infinity();
  const std::size_t found = impl_->tree->knnSearch(query.data(), 1, &index, &squared);
  if (found == 0) return std::numeric_limits<double>::infinity();
  return std::sqrt(squared);
}

std::vector<double> NearestNeighbourIndex::NearestDistances(const PointCloud& queries) const {
  std::vector<double> distances(queries.size());
  for (std::size_t i = 0; i < queries.size(); ++i) {
    distances[i] = NearestDistance(queries[i].cast<double>());
  }
  return distances;
}

void CloudMetricOptions::Check() const {
  if (!(std::isfinite(tau) && tau > 0)) {
    throw std::invalid_argument("tau must be a positive distance, got " + std::to_string(tau));
  }
  if (!(std::isfinite(cutoff) && cutoff > 0)) {
    throw std::invalid_argument("the outlier cut-off must be a positive distance, got " +
                                std::to_string(cutoff));
  }
}

CloudMetrics EvaluateCloud(const NearestNeighbourIndex& reconstruction,
                           const NearestNeighbourIndex& gt, const CloudMetricOptions& options) {
  CheckGt(gt.size(), options);
  return Combine(gt.NearestDistances(reconstruction.points()),
                 reconstruction.NearestDistances(gt.points()), options);
}

CloudMetrics EvaluateCloudBruteForce(const PointCloud& reconstruction, const PointCloud& gt,
                                     const CloudMetricOptions& options) {
  CheckGt(gt.size(), options);
  const auto nearest = [](const PointCloud& queries, const PointCloud& targets) {
    std::vector<double> distances(queries.size(), std::numeric_limits<double>::infinity());
    for (std::size_t i = 0; i < queries.size(); ++i) {
      const Eigen::Vector3d q = queries[i].cast<double>();
      double best = std::numeric_limits<double>::infinity();
      for (const Eigen::Vector3f& t : targets) {
        best = std::min(best, (t.cast<double>() - q).squaredNorm());
      }
      distances[i] = std::sqrt(best);
    }
    return distances;
  };
  return Combine(nearest(reconstruction, gt), nearest(gt, reconstruction), options);
}

int64_t AppendFinitePoints(const std::vector<colmap_io::PlyPoint>& ply, PointCloud* cloud) {
  int64_t dropped = 0;
  cloud->reserve(cloud->size() + ply.size());
  for (const colmap_io::PlyPoint& p : ply) {
    const Eigen::Vector3f xyz(p.xyz[0], p.xyz[1], p.xyz[2]);
    if (xyz.allFinite()) {
      cloud->push_back(xyz);
    } else {
      ++dropped;
    }
  }
  return dropped;
}

double BoundingBoxDiagonal(const PointCloud& points) {
  if (points.empty()) return 0;
  Eigen::Vector3d low = points.front().cast<double>();
  Eigen::Vector3d high = low;
  for (const Eigen::Vector3f& p : points) {
    low = low.cwiseMin(p.cast<double>());
    high = high.cwiseMax(p.cast<double>());
  }
  return (high - low).norm();
}

void BackProjectDepthMap(const colmap_io::DenseArray& depth, const colmap_io::Camera& camera,
                         const colmap_io::Image& image, int stride, PointCloud* points) {
  if (stride < 1) throw std::invalid_argument("stride must be >= 1");
  if (depth.channels() != 1) throw std::invalid_argument("a depth map must have 1 channel");
  const int width = depth.width();
  const int height = depth.height();
  if (camera.width > colmap_io::kMaxDenseArraySide ||
      camera.height > colmap_io::kMaxDenseArraySide ||
      !IsCleanScale(width, height, static_cast<int>(camera.width),
                    static_cast<int>(camera.height))) {
    throw std::invalid_argument("depth map is " + std::to_string(width) + "x" +
                                std::to_string(height) + " but its camera is " +
                                std::to_string(camera.width) + "x" +
                                std::to_string(camera.height) +
                                ": not the same size nor a down-scale of it by one factor");
  }
  const Eigen::Matrix3d K_inverse = camera.CalibrationMatrix().inverse();
  const Eigen::Matrix3d R_transposed = image.RotationMatrix().transpose();
  const Eigen::Vector3d t = image.tvec;
  // Image position of map index i: i / s = i * camera_size / map_size.
  const double to_image_x = static_cast<double>(camera.width) / width;
  const double to_image_y = static_cast<double>(camera.height) / height;
  for (int row = 0; row < height; row += stride) {
    for (int col = 0; col < width; col += stride) {
      const float d = depth.data()[static_cast<std::size_t>(row) * width + col];
      if (!(std::isfinite(d) && d > 0)) continue;
      const Eigen::Vector3d ray = K_inverse * Eigen::Vector3d(col * to_image_x, row * to_image_y, 1);
      const Eigen::Vector3d world = R_transposed * (static_cast<double>(d) * ray - t);
      points->push_back(world.cast<float>());
    }
  }
}

}  // namespace dispmvs::eval
