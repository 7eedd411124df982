#include "tests/support/model_builder.h"

#include <stdexcept>

#include <Eigen/Geometry>

namespace dispmvs::testing {

using colmap_io::camera_t;
using colmap_io::image_t;
using colmap_io::point3D_t;

Eigen::Matrix3d LookAtRotation(const Eigen::Vector3d& centre, const Eigen::Vector3d& target,
                               const Eigen::Vector3d& up) {
  const Eigen::Vector3d forward = target - centre;
  const Eigen::Vector3d down = -up;
  if (forward.norm() == 0.0 || forward.cross(down).norm() <= 1e-12 * forward.norm() * down.norm()) {
    throw std::invalid_argument("LookAtRotation: viewing direction is zero or parallel to up");
  }
  // Camera axes in world coordinates; they are the rows of world->camera R.
  const Eigen::Vector3d z = forward.normalized();
  const Eigen::Vector3d x = down.cross(z).normalized();  // x = y cross z
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d R;
  R.row(0) = x.transpose();
  R.row(1) = y.transpose();
  R.row(2) = z.transpose();
  return R;
}

camera_t ModelBuilder::AddPinholeCamera(int width, int height, double fx, double fy, double cx,
                                        double cy) {
  colmap_io::Camera camera;
  camera.camera_id = static_cast<camera_t>(model_.cameras.size() + 1);
  camera.model_id = 1;  // PINHOLE
  camera.width = static_cast<uint64_t>(width);
  camera.height = static_cast<uint64_t>(height);
  camera.params = {fx, fy, cx, cy};
  model_.cameras[camera.camera_id] = camera;
  return camera.camera_id;
}

image_t ModelBuilder::AddImageLookingAt(camera_t camera_id, const std::string& name,
                                        const Eigen::Vector3d& centre,
                                        const Eigen::Vector3d& target,
                                        const Eigen::Vector3d& up) {
  const Eigen::Matrix3d R = LookAtRotation(centre, target, up);
  return AddImageWithPose(camera_id, name, R, -R * centre);
}

image_t ModelBuilder::AddImageWithPose(camera_t camera_id, const std::string& name,
                                       const Eigen::Matrix3d& R_world_to_camera,
                                       const Eigen::Vector3d& t_world_to_camera) {
  if (model_.cameras.count(camera_id) == 0) {
    throw std::invalid_argument("ModelBuilder: unknown camera id " + std::to_string(camera_id));
  }
  colmap_io::Image image;
  image.image_id = static_cast<image_t>(model_.images.size() + 1);
  image.SetPose(R_world_to_camera, t_world_to_camera);
  image.camera_id = camera_id;
  image.name = name;
  model_.images[image.image_id] = image;
  return image.image_id;
}

point3D_t ModelBuilder::AddPoint(const Eigen::Vector3d& xyz,
                                 const std::vector<image_t>& observers) {
  colmap_io::Point3D point;
  point.point3D_id = next_point3D_id_++;
  point.xyz = xyz;
  point.error = 0.0;
  std::vector<std::pair<image_t, Eigen::Vector2d>> observations;
  for (const image_t image_id : observers) observations.emplace_back(image_id, Project(image_id, xyz));
  model_.AddObservedPoint(point, observations);
  return point.point3D_id;
}

void ModelBuilder::AddUnmatchedObservation(image_t image_id, const Eigen::Vector2d& xy) {
  colmap_io::Point2D point2D;
  point2D.xy = xy;
  model_.images.at(image_id).points2D.push_back(point2D);
}

namespace {

// Computed here from qvec rather than with Image::RotationMatrix() so that
// tests built with this helper check the library against an independent path.
Eigen::Vector3d ToCameraFrame(const colmap_io::Image& image, const Eigen::Vector3d& xyz) {
  const Eigen::Quaterniond q(image.qvec(0), image.qvec(1), image.qvec(2), image.qvec(3));
  return q.normalized().toRotationMatrix() * xyz + image.tvec;
}

}  // namespace

Eigen::Vector2d ModelBuilder::Project(image_t image_id, const Eigen::Vector3d& xyz) const {
  const auto& image = model_.images.at(image_id);
  const auto& params = model_.cameras.at(image.camera_id).params;
  const Eigen::Vector3d p = ToCameraFrame(image, xyz);
  if (p.z() == 0.0) return Eigen::Vector2d::Zero();
  return Eigen::Vector2d(params[0] * p.x() / p.z() + params[2],
                         params[1] * p.y() / p.z() + params[3]);
}

double ModelBuilder::Depth(image_t image_id, const Eigen::Vector3d& xyz) const {
  return ToCameraFrame(model_.images.at(image_id), xyz).z();
}

}  // namespace dispmvs::testing
