#include "eval/cloud_render.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>

namespace dispmvs::eval {

std::vector<cv::Mat> RenderCloudViews(const std::vector<colmap_io::PlyPoint>& points, int size) {
  const cv::Scalar background(40, 40, 40);
  std::vector<cv::Mat> views(3);
  for (cv::Mat& view : views) view = cv::Mat(size, size, CV_8UC3, background);
  std::vector<Eigen::Vector3d> xyz;
  std::vector<cv::Vec3b> bgr;
  for (const colmap_io::PlyPoint& p : points) {
    const Eigen::Vector3d x(p.xyz[0], p.xyz[1], p.xyz[2]);
    if (!x.allFinite()) continue;
    xyz.push_back(x);
    bgr.emplace_back(p.rgb[2], p.rgb[1], p.rgb[0]);
  }
  if (xyz.empty()) return views;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& x : xyz) mean += x;
  mean /= static_cast<double>(xyz.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const auto& x : xyz) covariance += (x - mean) * (x - mean).transpose();
  // Eigenvalues ascending: axis 0 is the thinnest direction (the view "from
  // above" for a scene on the ground).
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  const Eigen::Matrix3d axes = solver.eigenvectors();
  const int splat = std::max(1, size / 200);
  for (int v = 0; v < 3; ++v) {
    // Looking along axis v; the image spans the other two.
    const Eigen::Vector3d depth_axis = axes.col(v);
    const Eigen::Vector3d u_axis = axes.col((v + 2) % 3), w_axis = axes.col((v + 1) % 3);
    double u_min = std::numeric_limits<double>::max(), u_max = -u_min;
    double w_min = u_min, w_max = -u_min;
    for (const auto& x : xyz) {
      const double u = (x - mean).dot(u_axis), w = (x - mean).dot(w_axis);
      u_min = std::min(u_min, u);
      u_max = std::max(u_max, u);
      w_min = std::min(w_min, w);
      w_max = std::max(w_max, w);
    }
    const double extent = std::max({u_max - u_min, w_max - w_min, 1e-12});
    const double scale = 0.9 * size / extent;
    const double u_centre = 0.5 * (u_min + u_max), w_centre = 0.5 * (w_min + w_max);
    cv::Mat zbuffer(size, size, CV_64F, cv::Scalar(std::numeric_limits<double>::infinity()));
    for (std::size_t i = 0; i < xyz.size(); ++i) {
      const Eigen::Vector3d d = xyz[i] - mean;
      const int col = static_cast<int>(std::lround(0.5 * size + (d.dot(u_axis) - u_centre) * scale));
      const int row = static_cast<int>(std::lround(0.5 * size - (d.dot(w_axis) - w_centre) * scale));
      const double z = d.dot(depth_axis);
      for (int r = row - splat; r <= row + splat; ++r) {
        for (int c = col - splat; c <= col + splat; ++c) {
          if (r < 0 || c < 0 || r >= size || c >= size || z >= zbuffer.at<double>(r, c)) continue;
          zbuffer.at<double>(r, c) = z;
          views[v].at<cv::Vec3b>(r, c) = bgr[i];
        }
      }
    }
  }
  return views;
}

}  // namespace dispmvs::eval
