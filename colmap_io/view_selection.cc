#include "colmap_io/view_selection.h"

#include <algorithm>
#include <cmath>
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

}  // namespace dispmvs::colmap_io
