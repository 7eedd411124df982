#include "colmap_io/view_selection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <stdexcept>
#include <string>

namespace dispmvs::colmap_io {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Angle at X between the rays X - c1 and X - c2, folded to the acute side:
// COLMAP treats very acute (far points) and very obtuse (close points) angles
// alike, as both triangulate badly. atan2 keeps small angles accurate where
// acos of a near-1 cosine would not. Coincident centres (or X on a centre)
// give 0.
double TriangulationAngle(const Eigen::Vector3d& c1, const Eigen::Vector3d& c2,
                          const Eigen::Vector3d& x) {
  const Eigen::Vector3d ray1 = x - c1;
  const Eigen::Vector3d ray2 = x - c2;
  const double sine_part = ray1.cross(ray2).norm();
  const double cosine_part = ray1.dot(ray2);
  if (sine_part == 0.0 && cosine_part == 0.0) return 0.0;
  const double angle = std::atan2(sine_part, cosine_part);
  return std::min(angle, kPi - angle);
}

// COLMAP's Percentile(): the element at round(p / 100 * (n - 1)) in sorted order.
double PickPercentile(std::vector<double> values, double percentile) {
  const double position = percentile / 100.0 * static_cast<double>(values.size() - 1);
  const auto index = std::min(static_cast<std::size_t>(std::llround(position)),
                              values.size() - 1);
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(index),
                   values.end());
  return values[index];
}

}  // namespace

void ViewSelectionOptions::Check() const {
  if (!(min_triangulation_angle_deg >= 0.0 && min_triangulation_angle_deg <= 90.0)) {
    throw std::invalid_argument(
        "ViewSelectionOptions.min_triangulation_angle_deg must be in [0, 90], got " +
        std::to_string(min_triangulation_angle_deg));
  }
  if (!(triangulation_angle_percentile >= 0.0 && triangulation_angle_percentile <= 100.0)) {
    throw std::invalid_argument(
        "ViewSelectionOptions.triangulation_angle_percentile must be in [0, 100], got " +
        std::to_string(triangulation_angle_percentile));
  }
  if (!(max_viewing_angle_deg > 0.0 && max_viewing_angle_deg <= 180.0)) {
    throw std::invalid_argument(
        "ViewSelectionOptions.max_viewing_angle_deg must be in (0, 180], got " +
        std::to_string(max_viewing_angle_deg));
  }
}

std::vector<SourceViewCandidate> RankSourceViews(const SparseModel& model,
                                                 image_t reference_image_id,
                                                 const ViewSelectionOptions& options) {
  options.Check();
  const auto reference_it = model.images.find(reference_image_id);
  if (reference_it == model.images.end()) {
    throw std::invalid_argument("RankSourceViews: no image with id " +
                                std::to_string(reference_image_id) + " in the model");
  }
  const Image& reference = reference_it->second;
  const Eigen::Vector3d reference_centre = reference.ProjectionCenter();

  // A point observed twice by the reference must still count once.
  std::set<point3D_t> reference_points;
  for (const Point2D& point2D : reference.points2D) {
    if (point2D.HasPoint3D()) reference_points.insert(point2D.point3D_id);
  }

  // Per other image: the triangulation angle of every shared point.
  std::map<image_t, std::vector<double>> angles_by_image;
  std::map<image_t, Eigen::Vector3d> centres;
  for (const point3D_t point3D_id : reference_points) {
    const auto point_it = model.points3D.find(point3D_id);
    if (point_it == model.points3D.end()) continue;
    const Point3D& point = point_it->second;
    std::set<image_t> observers;
    for (const TrackElement& element : point.track) {
      if (element.image_id != reference_image_id) observers.insert(element.image_id);
    }
    for (const image_t other_id : observers) {
      auto centre_it = centres.find(other_id);
      if (centre_it == centres.end()) {
        const auto other_it = model.images.find(other_id);
        if (other_it == model.images.end()) continue;
        centre_it = centres.emplace(other_id, other_it->second.ProjectionCenter()).first;
      }
      angles_by_image[other_id].push_back(
          TriangulationAngle(reference_centre, centre_it->second, point.xyz));
    }
  }

  std::vector<SourceViewCandidate> candidates;
  const double min_angle_rad = options.min_triangulation_angle_deg * kPi / 180.0;
  for (const auto& [other_id, angles] : angles_by_image) {
    const double angle = PickPercentile(angles, options.triangulation_angle_percentile);
    if (!(angle >= min_angle_rad)) continue;
    SourceViewCandidate candidate;
    candidate.image_id = other_id;
    candidate.num_shared_points = angles.size();
    candidate.triangulation_angle_deg = angle * 180.0 / kPi;
    candidates.push_back(candidate);
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const SourceViewCandidate& a, const SourceViewCandidate& b) {
              if (a.num_shared_points != b.num_shared_points) {
                return a.num_shared_points > b.num_shared_points;
              }
              return a.image_id < b.image_id;
            });
  return candidates;
}

std::vector<image_t> SelectSourceViews(const SparseModel& model, image_t reference_image_id,
                                       std::size_t max_num_source_views,
                                       const ViewSelectionOptions& options) {
  const auto candidates = RankSourceViews(model, reference_image_id, options);
  std::vector<image_t> selected;
  const std::size_t count = std::min(max_num_source_views, candidates.size());
  selected.reserve(count);
  for (std::size_t i = 0; i < count; ++i) selected.push_back(candidates[i].image_id);
  return selected;
}

bool SharesSparsePoints(const SparseModel& model, image_t reference_image_id) {
  const auto reference_it = model.images.find(reference_image_id);
  if (reference_it == model.images.end()) {
    throw std::invalid_argument("SharesSparsePoints: no image with id " +
                                std::to_string(reference_image_id) + " in the model");
  }
  for (const Point2D& point2D : reference_it->second.points2D) {
    if (!point2D.HasPoint3D()) continue;
    const auto point_it = model.points3D.find(point2D.point3D_id);
    if (point_it == model.points3D.end()) continue;
    for (const TrackElement& element : point_it->second.track) {
      // The same images RankSourceViews would consider.
      if (element.image_id != reference_image_id && model.images.count(element.image_id) > 0) {
        return true;
      }
    }
  }
  return false;
}

std::vector<PoseSourceViewCandidate> RankSourceViewsByPose(const SparseModel& model,
                                                           image_t reference_image_id,
                                                           double depth_min, double depth_max,
                                                           const ViewSelectionOptions& options) {
  options.Check();
  if (!(depth_min > 0.0 && depth_min <= depth_max && std::isfinite(depth_max))) {
    throw std::invalid_argument("RankSourceViewsByPose: need 0 < depth_min <= depth_max, got " +
                                std::to_string(depth_min) + ", " + std::to_string(depth_max));
  }
  const auto reference_it = model.images.find(reference_image_id);
  if (reference_it == model.images.end()) {
    throw std::invalid_argument("RankSourceViewsByPose: no image with id " +
                                std::to_string(reference_image_id) + " in the model");
  }
  const Image& reference = reference_it->second;
  const Camera& reference_camera = model.cameras.at(reference.camera_id);
  const Eigen::Vector3d reference_centre = reference.ProjectionCenter();
  const Eigen::Vector3d reference_axis = reference.ViewingDirection();

  // The virtual points, in world coordinates. Pixel (x, y) in COLMAP's
  // convention (the image spans [0, w] x [0, h]) at camera depth z is
  // z K^-1 (x, y, 1).
  const Eigen::Matrix3d reference_K_inverse = reference_camera.CalibrationMatrix().inverse();
  const Eigen::Matrix3d reference_R_transpose = reference.RotationMatrix().transpose();
  std::vector<Eigen::Vector3d> samples;
  samples.reserve(kPoseSampleGrid * kPoseSampleGrid * kPoseSampleDepths);
  for (int k = 0; k < kPoseSampleDepths; ++k) {
    const double fraction = kPoseSampleDepths == 1 ? 0.0 : k / (kPoseSampleDepths - 1.0);
    const double depth = depth_min * std::pow(depth_max / depth_min, fraction);
    for (int row = 0; row < kPoseSampleGrid; ++row) {
      for (int col = 0; col < kPoseSampleGrid; ++col) {
        const Eigen::Vector3d pixel((col + 0.5) / kPoseSampleGrid * reference_camera.width,
                                    (row + 0.5) / kPoseSampleGrid * reference_camera.height, 1);
        const Eigen::Vector3d camera_point = depth * (reference_K_inverse * pixel);
        samples.push_back(reference_R_transpose * (camera_point - reference.tvec));
      }
    }
  }

  const double min_angle_rad = options.min_triangulation_angle_deg * kPi / 180.0;
  const double max_viewing_angle_rad = options.max_viewing_angle_deg * kPi / 180.0;
  std::vector<PoseSourceViewCandidate> candidates;
  std::vector<double> angles;
  for (const auto& [other_id, other] : model.images) {
    if (other_id == reference_image_id) continue;
    const Eigen::Vector3d other_axis = other.ViewingDirection();
    const double viewing_angle = std::atan2(reference_axis.cross(other_axis).norm(),
                                            reference_axis.dot(other_axis));
    if (!(viewing_angle <= max_viewing_angle_rad)) continue;
    const Camera& camera = model.cameras.at(other.camera_id);
    const Eigen::Matrix3d K = camera.CalibrationMatrix();
    const Eigen::Matrix3d R = other.RotationMatrix();
    const Eigen::Vector3d centre = other.ProjectionCenter();
    const double width = static_cast<double>(camera.width);
    const double height = static_cast<double>(camera.height);
    angles.clear();
    for (const Eigen::Vector3d& sample : samples) {
      const Eigen::Vector3d projected = K * (R * sample + other.tvec);
      if (!(projected.z() > 0.0)) continue;  // behind the camera or on its plane
      const double x = projected.x() / projected.z();
      const double y = projected.y() / projected.z();
      if (!(x >= 0.0 && x <= width && y >= 0.0 && y <= height)) continue;
      angles.push_back(TriangulationAngle(reference_centre, centre, sample));
    }
    if (angles.empty()) continue;
    const double angle = PickPercentile(angles, options.triangulation_angle_percentile);
    if (!(angle >= min_angle_rad)) continue;
    PoseSourceViewCandidate candidate;
    candidate.image_id = other_id;
    candidate.num_shared_samples = angles.size();
    candidate.triangulation_angle_deg = angle * 180.0 / kPi;
    candidate.viewing_angle_deg = viewing_angle * 180.0 / kPi;
    candidates.push_back(candidate);
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const PoseSourceViewCandidate& a, const PoseSourceViewCandidate& b) {
              if (a.num_shared_samples != b.num_shared_samples) {
                return a.num_shared_samples > b.num_shared_samples;
              }
              return a.image_id < b.image_id;
            });
  return candidates;
}

std::vector<image_t> SelectSourceViewsByPose(const SparseModel& model, image_t reference_image_id,
                                             std::size_t max_num_source_views, double depth_min,
                                             double depth_max,
                                             const ViewSelectionOptions& options) {
  const auto candidates =
      RankSourceViewsByPose(model, reference_image_id, depth_min, depth_max, options);
  std::vector<image_t> selected;
  const std::size_t count = std::min(max_num_source_views, candidates.size());
  selected.reserve(count);
  for (std::size_t i = 0; i < count; ++i) selected.push_back(candidates[i].image_id);
  return selected;
}

std::optional<std::pair<double, double>> GuessSampleDepthsFromPoses(const SparseModel& model) {
  std::vector<Eigen::Vector3d> centres;
  centres.reserve(model.images.size());
  for (const auto& [image_id, image] : model.images) centres.push_back(image.ProjectionCenter());
  if (centres.size() < 2) return std::nullopt;
  std::vector<double> nearest(centres.size(), std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < centres.size(); ++i) {
    for (std::size_t j = i + 1; j < centres.size(); ++j) {
      const double distance = (centres[i] - centres[j]).norm();
      nearest[i] = std::min(nearest[i], distance);
      nearest[j] = std::min(nearest[j], distance);
    }
  }
  const double baseline = PickPercentile(nearest, 50.0);
  if (!(baseline > 0.0) || !std::isfinite(baseline)) return std::nullopt;
  return std::make_pair(2.0 * baseline, 100.0 * baseline);
}

PoseSampleDepths::PoseSampleDepths(const SparseModel& model,
                                   const std::map<image_t, DepthRange>& ranges)
    : model_(model), ranges_(ranges), fallback_(FallbackDepthRange(ranges)) {}

std::optional<std::pair<double, double>> PoseSampleDepths::For(image_t reference_image_id) {
  const auto own = ranges_.find(reference_image_id);
  if (own != ranges_.end() && own->second.valid) {
    return std::make_pair(own->second.d_min, own->second.d_max);
  }
  if (fallback_.valid) return std::make_pair(fallback_.d_min, fallback_.d_max);
  if (!guess_tried_) {
    guessed_ = GuessSampleDepthsFromPoses(model_);
    guess_tried_ = true;
  }
  return guessed_;
}

}  // namespace dispmvs::colmap_io
