#include "eval/error_regions.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

namespace dispmvs::eval {
namespace {

constexpr uint8_t kNoSurface = 255;
// Distance given where a map has no depth edge at all: beyond every ring.
constexpr int kNoEdge = std::numeric_limits<int>::max();

bool IsSurface(float depth) { return std::isfinite(depth) && depth > 0; }

void CheckMap(const colmap_io::DenseArray& gt, const colmap_io::Camera& camera, const char* what) {
  if (gt.channels() != 1 || gt.width() < 1 || gt.height() < 1) {
    throw std::invalid_argument(std::string(what) + ": a ground-truth depth map must have 1 channel and pixels");
  }
  if (!IsCleanScale(gt.width(), gt.height(), static_cast<int>(camera.width), static_cast<int>(camera.height))) {
    throw std::invalid_argument(std::string(what) + ": ground-truth depth map " + std::to_string(gt.width()) + "x" +
                                std::to_string(gt.height()) + " is not a clean scale of its camera " +
                                std::to_string(camera.width) + "x" + std::to_string(camera.height));
  }
}

// Image position of GT pixel index i along an axis: i * camera_size / map_size.
double ToImage(int index, int64_t camera_size, int map_size) {
  return index * static_cast<double>(camera_size) / map_size;
}

// How one other view sees world point X: outside, hidden behind its GT
// surface (or where it has none), or seen.
Visibility SeenBy(const OtherView& view, const Eigen::Matrix3d& K, const Eigen::Matrix3d& R,
                  const Eigen::Vector3d& X) {
  const Eigen::Vector3d in_camera = R * X + view.image->tvec;
  const double z = in_camera.z();
  if (!(z > 0)) return Visibility::kOutside;
  const Eigen::Vector3d projected = K * (in_camera / z);
  // Image position -> the other view's GT grid (a clean scale of its camera).
  const double sx = view.gt->width() / static_cast<double>(view.camera->width);
  const double sy = view.gt->height() / static_cast<double>(view.camera->height);
  const double u = projected.x() * sx, v = projected.y() * sy;
  if (!(u >= -0.5 && u < view.gt->width() - 0.5 && v >= -0.5 && v < view.gt->height() - 0.5)) {
    return Visibility::kOutside;
  }
  const int col = static_cast<int>(std::floor(u + 0.5)), row = static_cast<int>(std::floor(v + 0.5));
  const float there = view.gt->data()[static_cast<size_t>(row) * view.gt->width() + col];
  // No GT surface there (a hole of the sensor's): nothing says it is hidden.
  if (IsSurface(there) && z > there * (1 + kHiddenDepthTolerance)) return Visibility::kHidden;
  return Visibility::kSeen;
}

}  // namespace

RegionClassSums& RegionClassSums::operator+=(const RegionClassSums& other) {
  gt_pixels += other.gt_pixels;
  within_1 += other.within_1;
  within_2 += other.within_2;
  within_5 += other.within_5;
  return *this;
}

ErrorRegionSums& ErrorRegionSums::operator+=(const ErrorRegionSums& other) {
  for (int i = 0; i < kNumVisibilities; ++i) visibility[i] += other.visibility[i];
  for (int i = 0; i < kNumEdgeRings; ++i) seen_by_edge_ring[i] += other.seen_by_edge_ring[i];
  gt_pixels += other.gt_pixels;
  return *this;
}

cv::Mat LabelVisibility(const colmap_io::DenseArray& gt, const colmap_io::Camera& camera,
                        const colmap_io::Image& image, const std::vector<OtherView>& others) {
  CheckMap(gt, camera, "the view");
  std::vector<Eigen::Matrix3d> K(others.size()), R(others.size());
  for (size_t i = 0; i < others.size(); ++i) {
    CheckMap(*others[i].gt, *others[i].camera, "another view");
    K[i] = others[i].camera->CalibrationMatrix();
    R[i] = others[i].image->RotationMatrix();
  }
  const Eigen::Matrix3d K_inverse = camera.CalibrationMatrix().inverse();
  const Eigen::Matrix3d R_transposed = image.RotationMatrix().transpose();
  cv::Mat labels(gt.height(), gt.width(), CV_8UC1, cv::Scalar(kNoSurface));
  for (int row = 0; row < gt.height(); ++row) {
    for (int col = 0; col < gt.width(); ++col) {
      const float depth = gt.data()[static_cast<size_t>(row) * gt.width() + col];
      if (!IsSurface(depth)) continue;
      const Eigen::Vector3d ray = K_inverse * Eigen::Vector3d(ToImage(col, camera.width, gt.width()),
                                                              ToImage(row, camera.height, gt.height()), 1.0);
      const Eigen::Vector3d X = R_transposed * (depth * ray - image.tvec);
      Visibility best = Visibility::kOutside;
      for (size_t i = 0; i < others.size() && best != Visibility::kSeen; ++i) {
        const Visibility v = SeenBy(others[i], K[i], R[i], X);
        if (v == Visibility::kSeen || (v == Visibility::kHidden && best == Visibility::kOutside)) best = v;
      }
      labels.at<uint8_t>(row, col) = static_cast<uint8_t>(best);
    }
  }
  return labels;
}

cv::Mat DistanceToDepthEdge(const colmap_io::DenseArray& gt) {
  if (gt.channels() != 1) throw std::invalid_argument("a ground-truth depth map must have 1 channel");
  const int width = gt.width(), height = gt.height();
  const auto depth = [&](int row, int col) { return gt.data()[static_cast<size_t>(row) * width + col]; };
  // Edge pixels are 0, the rest 1: distanceTransform measures to the nearest 0.
  cv::Mat not_edge(height, width, CV_8UC1, cv::Scalar(1));
  bool any_edge = false;
  const auto compare = [&](int r0, int c0, int r1, int c1) {
    const float a = depth(r0, c0), b = depth(r1, c1);
    if (IsSurface(a) && IsSurface(b) && std::abs(std::log(a) - std::log(b)) > kEdgeLogDepthStep) {
      not_edge.at<uint8_t>(r0, c0) = not_edge.at<uint8_t>(r1, c1) = 0;
      any_edge = true;
    }
  };
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      if (col + 1 < width) compare(row, col, row, col + 1);
      if (row + 1 < height) compare(row, col, row + 1, col);
    }
  }
  cv::Mat distance(height, width, CV_32SC1, cv::Scalar(kNoEdge));
  if (any_edge) {
    cv::Mat l1;
    // L1 with the 3x3 mask: exact (whole pixels along rows and columns).
    cv::distanceTransform(not_edge, l1, cv::DIST_L1, 3, CV_32F);
    l1.convertTo(distance, CV_32SC1);
  }
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      if (!IsSurface(depth(row, col))) distance.at<int>(row, col) = -1;
    }
  }
  return distance;
}

int EdgeRing(int distance) {
  for (int ring = 0; ring < static_cast<int>(kEdgeRingUpper.size()); ++ring) {
    if (distance <= kEdgeRingUpper[ring]) return ring;
  }
  return kNumEdgeRings - 1;
}

RegionLabels LabelRegions(const colmap_io::DenseArray& gt, const colmap_io::Camera& camera,
                          const colmap_io::Image& image, const std::vector<OtherView>& others) {
  RegionLabels labels;
  labels.visibility = LabelVisibility(gt, camera, image, others);
  const cv::Mat distance = DistanceToDepthEdge(gt);
  labels.edge_ring = cv::Mat(gt.height(), gt.width(), CV_8UC1, cv::Scalar(kNoSurface));
  for (int row = 0; row < gt.height(); ++row) {
    for (int col = 0; col < gt.width(); ++col) {
      const int d = distance.at<int>(row, col);
      if (d >= 0) labels.edge_ring.at<uint8_t>(row, col) = static_cast<uint8_t>(EdgeRing(d));
    }
  }
  return labels;
}

std::vector<std::pair<std::string, RegionClassSums>> RegionRows(const ErrorRegionSums& sums) {
  std::vector<std::pair<std::string, RegionClassSums>> rows = {
      {"seen by another view", sums.visibility[static_cast<int>(Visibility::kSeen)]},
      {"hidden in the others", sums.visibility[static_cast<int>(Visibility::kHidden)]},
      {"outside the others", sums.visibility[static_cast<int>(Visibility::kOutside)]}};
  int lower = 0;
  for (int ring = 0; ring < kNumEdgeRings; ++ring) {
    const std::string range = ring < static_cast<int>(kEdgeRingUpper.size())
                                  ? std::to_string(lower) + "-" + std::to_string(kEdgeRingUpper[ring])
                                  : std::to_string(lower) + "+";
    rows.push_back({"seen, " + range + " px from a depth edge", sums.seen_by_edge_ring[ring]});
    if (ring < static_cast<int>(kEdgeRingUpper.size())) lower = kEdgeRingUpper[ring] + 1;
  }
  return rows;
}

ErrorRegionSums SumErrorRegions(const cv::Mat& rel_error, const RegionLabels& labels) {
  if (rel_error.type() != CV_32FC1 || labels.visibility.type() != CV_8UC1 || labels.edge_ring.type() != CV_8UC1 ||
      labels.visibility.size() != labels.edge_ring.size() || rel_error.empty() || labels.visibility.empty() ||
      !IsCleanScale(rel_error.cols, rel_error.rows, labels.visibility.cols, labels.visibility.rows)) {
    throw std::invalid_argument("error regions: the relative errors must be a clean scale of the labels' GT map");
  }
  ErrorRegionSums sums;
  for (int row = 0; row < rel_error.rows; ++row) {
    const int gt_row = NearestGtIndex(row, rel_error.rows, labels.visibility.rows);
    for (int col = 0; col < rel_error.cols; ++col) {
      const float error = rel_error.at<float>(row, col);
      if (error == kRelErrorNoGt) continue;
      const int gt_col = NearestGtIndex(col, rel_error.cols, labels.visibility.cols);
      const uint8_t visibility = labels.visibility.at<uint8_t>(gt_row, gt_col);
      if (visibility == kNoSurface) continue;  // cannot happen for the GT SumDepthMetrics read
      RegionClassSums add;
      add.gt_pixels = 1;
      add.within_1 = error >= 0 && error < 0.01;
      add.within_2 = error >= 0 && error < 0.02;
      add.within_5 = error >= 0 && error < 0.05;
      sums.visibility[visibility] += add;
      if (visibility == static_cast<uint8_t>(Visibility::kSeen)) {
        sums.seen_by_edge_ring[labels.edge_ring.at<uint8_t>(gt_row, gt_col)] += add;
      }
      ++sums.gt_pixels;
    }
  }
  return sums;
}

}  // namespace dispmvs::eval
