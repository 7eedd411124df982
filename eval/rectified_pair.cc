#include "eval/rectified_pair.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Core>

namespace dispmvs::eval {
namespace {

bool NearlyEqual(double a, double b) {
  return std::abs(a - b) <= kRectifiedIntrinsicsTolerance * std::max(std::abs(a), std::abs(b));
}

}  // namespace

std::optional<double> RectifiedBaseline(const colmap_io::Camera& camera_a,
                                        const colmap_io::Image& image_a,
                                        const colmap_io::Camera& camera_b,
                                        const colmap_io::Image& image_b) {
  if (!camera_a.IsPinhole() || !camera_b.IsPinhole()) return std::nullopt;
  const Eigen::Matrix3d K_a = camera_a.CalibrationMatrix();
  const Eigen::Matrix3d K_b = camera_b.CalibrationMatrix();
  if (!NearlyEqual(K_a(0, 0), K_b(0, 0)) || !NearlyEqual(K_a(1, 1), K_b(1, 1)) ||
      !NearlyEqual(K_a(1, 2), K_b(1, 2))) {
    return std::nullopt;
  }
  const Eigen::Matrix3d R_a = image_a.RotationMatrix();
  const Eigen::Matrix3d R_b = image_b.RotationMatrix();
  if (!((R_a - R_b).cwiseAbs().maxCoeff() <= kRectifiedRotationTolerance)) return std::nullopt;
  const Eigen::Vector3d offset = image_b.ProjectionCenter() - image_a.ProjectionCenter();
  const double baseline = offset.norm();
  if (!(std::isfinite(baseline) && baseline > 0)) return std::nullopt;
  const Eigen::Vector3d in_camera = R_a * offset;
  const double limit = kRectifiedOffAxisTolerance * baseline;
  if (!(std::abs(in_camera.y()) < limit && std::abs(in_camera.z()) < limit)) return std::nullopt;
  return baseline;
}

std::optional<RectifiedPartner> FindRectifiedPartner(const colmap_io::SparseModel& model,
                                                     colmap_io::image_t image_id) {
  const colmap_io::Image& image = model.images.at(image_id);
  const colmap_io::Camera& camera = model.cameras.at(image.camera_id);
  std::optional<RectifiedPartner> best;
  for (const auto& [other_id, other] : model.images) {
    if (other_id == image_id) continue;
    const std::optional<double> baseline =
        RectifiedBaseline(camera, image, model.cameras.at(other.camera_id), other);
    if (!baseline) continue;
    // Baselines equal to rounding (a camera between two others) are a tie.
    const bool tie = NearlyEqual(*baseline, best ? best->baseline : 0.0);
    if (!best || (!tie && *baseline < best->baseline) || (tie && other.name < best->name)) {
      best = RectifiedPartner{other_id, other.name, *baseline};
    }
  }
  return best;
}

}  // namespace dispmvs::eval
