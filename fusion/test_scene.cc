#include "fusion/test_scene.h"

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace dispmvs::fusion::testing {

Camera LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target, int width, int height,
              double fx, double fy, double cx, double cy) {
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Camera camera;
  camera.R.row(0) = x.transpose();
  camera.R.row(1) = y.transpose();
  camera.R.row(2) = z.transpose();
  camera.t = -camera.R * centre;
  camera.K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  camera.width = width;
  camera.height = height;
  return camera;
}

Scene Scene::TwoPlanes() {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  Scene scene;
  scene.planes_.push_back(Plane{Eigen::Vector3d(0, 0, 10),
                                Eigen::Vector3d(0.1, -0.15, -1).normalized(), -kInf, kInf,
                                -kInf, kInf, {200, 60, 40}});
  scene.planes_.push_back(Plane{Eigen::Vector3d(0.1, 0.05, 5),
                                Eigen::Vector3d(-0.2, 0.1, -1).normalized(), -0.8, 1.0, -0.6,
                                0.7, {30, 170, 220}});
  return scene;
}

Hit Scene::RayCast(const Camera& camera, double col, double row) const {
  const Eigen::Vector3d ray_camera = camera.K.inverse() * Eigen::Vector3d(col, row, 1.0);
  const Eigen::Vector3d ray_world = camera.R.transpose() * ray_camera;
  const Eigen::Vector3d centre = camera.Centre();
  Hit best;
  for (std::size_t i = 0; i < planes_.size(); ++i) {
    const Plane& plane = planes_[i];
    const double denominator = plane.normal.dot(ray_world);
    if (std::abs(denominator) < 1e-12) continue;
    // ray_camera has z = 1, so the ray parameter is the camera depth.
    const double depth = plane.normal.dot(plane.point - centre) / denominator;
    if (!(depth > 0.0)) continue;
    const Eigen::Vector3d x = centre + depth * ray_world;
    if (x.x() < plane.x_min || x.x() > plane.x_max || x.y() < plane.y_min || x.y() > plane.y_max) {
      continue;
    }
    if (best.plane < 0 || depth < best.depth) {
      best.plane = static_cast<int>(i);
      best.depth = depth;
      best.world = x;
    }
  }
  return best;
}

colmap_io::DenseArray Scene::RenderDepth(const Camera& camera) const {
  colmap_io::DenseArray depth(camera.width, camera.height, 1, 0.0f);
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      const Hit hit = RayCast(camera, col, row);
      if (hit.plane >= 0) depth.at(row, col) = static_cast<float>(hit.depth);
    }
  }
  return depth;
}

colmap_io::DenseArray Scene::RenderNormals(const Camera& camera) const {
  colmap_io::DenseArray normals(camera.width, camera.height, 3, 0.0f);
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      const Hit hit = RayCast(camera, col, row);
      if (hit.plane < 0) continue;
      Eigen::Vector3d n = camera.R * planes_[hit.plane].normal;
      const Eigen::Vector3d x_camera = camera.R * hit.world + camera.t;
      if (n.dot(x_camera) > 0) n = -n;
      for (int c = 0; c < 3; ++c) normals.at(row, col, c) = static_cast<float>(n[c]);
    }
  }
  return normals;
}

cv::Mat Scene::RenderImage(const Camera& camera, int type) const {
  if (type != CV_8UC3 && type != CV_32FC3) throw std::invalid_argument("RenderImage: bad type");
  cv::Mat image(camera.height, camera.width, type, cv::Scalar::all(0));
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      const Hit hit = RayCast(camera, col, row);
      if (hit.plane < 0) continue;
      const auto& rgb = planes_[hit.plane].rgb;
      if (type == CV_8UC3) {
        image.at<cv::Vec3b>(row, col) = cv::Vec3b(rgb[0], rgb[1], rgb[2]);
      } else {
        image.at<cv::Vec3f>(row, col) =
            cv::Vec3f(rgb[0] / 255.0f, rgb[1] / 255.0f, rgb[2] / 255.0f);
      }
    }
  }
  return image;
}

Visibility Scene::Classify(const Camera& camera, const Eigen::Vector3d& x, int plane) const {
  const Eigen::Vector3d projected = camera.K * (camera.R * x + camera.t);
  if (!(projected.z() > 0.0)) return Visibility::kHidden;
  const double col = projected.x() / projected.z();
  const double row = projected.y() / projected.z();
  int num_seen = 0;
  for (int dr = -1; dr <= 1; ++dr) {
    for (int dc = -1; dc <= 1; ++dc) {
      const double c = col + dc;
      const double r = row + dr;
      // Inside once rounded to the nearest pixel.
      const bool inside = c > -0.5 && c < camera.width - 0.5 && r > -0.5 && r < camera.height - 0.5;
      if (inside && RayCast(camera, c, r).plane == plane) ++num_seen;
    }
  }
  if (num_seen == 9) return Visibility::kVisible;
  if (num_seen == 0) return Visibility::kHidden;
  return Visibility::kUndecided;
}

std::vector<Camera> DefaultCameras(int count) {
  const Eigen::Vector3d target(0.2, 0.1, 10);
  const std::vector<Eigen::Vector3d> centres = {
      Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(-1.0, 0.05, 0.1),
      Eigen::Vector3d(1.0, -0.1, -0.1), Eigen::Vector3d(0.1, -0.9, 0.2)};
  if (count < 1 || count > static_cast<int>(centres.size())) {
    throw std::invalid_argument("DefaultCameras: count must be 1..4");
  }
  std::vector<Camera> cameras;
  for (int i = 0; i < count; ++i) {
    cameras.push_back(LookAt(centres[i], target, 80, 60, 62.0, 58.0, 40.7, 28.3));
  }
  return cameras;
}

DepthView MakeDepthView(const Camera& camera, const colmap_io::DenseArray& depth) {
  DepthView view;
  view.K = camera.K;
  view.R = camera.R;
  view.t = camera.t;
  view.depth = depth;
  return view;
}

}  // namespace dispmvs::fusion::testing
