#include "eval/cloud_render.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>

#include <Eigen/Dense>

namespace dispmvs::eval {
namespace {

const cv::Scalar kBackground(40, 40, 40);
// Percentiles are taken over at most this many points (every k-th): the
// frame of a 20-million-point cloud does not need all of them.
constexpr std::size_t kMaxSampledPoints = 200000;
// The share of the points nearest the median centre that give the axes.
constexpr double kCoreShare = 0.95;
// The percentiles of each picture's coordinates that fill it.
constexpr double kLowPercentile = 0.01, kHighPercentile = 0.99;
// The picture's share filled by that extent (the rest is margin).
constexpr double kFill = 0.9;
constexpr int kMaxSplatRadius = 4;

struct Cloud {
  std::vector<Eigen::Vector3d> xyz;
  std::vector<cv::Vec3b> bgr;
};

Cloud FinitePoints(const std::vector<colmap_io::PlyPoint>& points) {
  Cloud cloud;
  cloud.xyz.reserve(points.size());
  cloud.bgr.reserve(points.size());
  for (const colmap_io::PlyPoint& p : points) {
    const Eigen::Vector3d x(p.xyz[0], p.xyz[1], p.xyz[2]);
    if (!x.allFinite()) continue;
    cloud.xyz.push_back(x);
    cloud.bgr.emplace_back(p.rgb[2], p.rgb[1], p.rgb[0]);
  }
  return cloud;
}

// The value at `share` (0..1) of `values` (reordered).
double Percentile(std::vector<double>* values, double share) {
  const std::size_t k = std::min(values->size() - 1,
                                 static_cast<std::size_t>(share * static_cast<double>(values->size())));
  std::nth_element(values->begin(), values->begin() + static_cast<std::ptrdiff_t>(k), values->end());
  return (*values)[k];
}

// Every k-th point, at most kMaxSampledPoints of them (non-empty input).
std::vector<Eigen::Vector3d> Sample(const std::vector<Eigen::Vector3d>& xyz) {
  const std::size_t stride = std::max<std::size_t>(1, xyz.size() / kMaxSampledPoints);
  std::vector<Eigen::Vector3d> sample;
  for (std::size_t i = 0; i < xyz.size(); i += stride) sample.push_back(xyz[i]);
  return sample;
}

// The splat radius at which `drawn` points cover a quarter of `pixels` about
// twice over: 0 (one pixel each) for dense clouds, up to kMaxSplatRadius.
int SplatRadius(std::size_t drawn, double pixels) {
  if (drawn == 0) return 0;
  const double side = std::sqrt(0.5 * pixels / static_cast<double>(drawn));
  return std::clamp(static_cast<int>(std::ceil((side - 1.0) / 2.0)), 0, kMaxSplatRadius);
}

// A picture being drawn: colours and the depth of what each pixel shows.
struct Canvas {
  cv::Mat image;
  cv::Mat depth;  // CV_64F, +inf where empty

  Canvas(int rows, int cols)
      : image(rows, cols, CV_8UC3, kBackground),
        depth(rows, cols, CV_64F, cv::Scalar(std::numeric_limits<double>::infinity())) {}

  void Splat(double row, double col, double z, int radius, const cv::Vec3b& colour) {
    const int r0 = static_cast<int>(std::lround(row)), c0 = static_cast<int>(std::lround(col));
    for (int r = std::max(r0 - radius, 0); r <= std::min(r0 + radius, image.rows - 1); ++r) {
      for (int c = std::max(c0 - radius, 0); c <= std::min(c0 + radius, image.cols - 1); ++c) {
        if (z >= depth.at<double>(r, c)) continue;
        depth.at<double>(r, c) = z;
        image.at<cv::Vec3b>(r, c) = colour;
      }
    }
  }

  // An empty pixel with at least 5 of its 8 neighbours drawn lies inside a
  // surface the points sample a little too sparsely: it takes the nearest
  // of those neighbours. Edges (fewer drawn neighbours) stay sharp.
  void CloseHoles() {
    const cv::Mat drawn_depth = depth.clone();
    const cv::Mat drawn_image = image.clone();
    for (int r = 1; r + 1 < image.rows; ++r) {
      for (int c = 1; c + 1 < image.cols; ++c) {
        if (std::isfinite(drawn_depth.at<double>(r, c))) continue;
        int neighbours = 0, best_r = 0, best_c = 0;
        double best = std::numeric_limits<double>::infinity();
        for (int dr = -1; dr <= 1; ++dr) {
          for (int dc = -1; dc <= 1; ++dc) {
            const double z = drawn_depth.at<double>(r + dr, c + dc);
            if (!std::isfinite(z)) continue;
            ++neighbours;
            if (z < best) best = z, best_r = r + dr, best_c = c + dc;
          }
        }
        if (neighbours < 5) continue;
        depth.at<double>(r, c) = best;
        image.at<cv::Vec3b>(r, c) = drawn_image.at<cv::Vec3b>(best_r, best_c);
      }
    }
  }
};

}  // namespace

std::vector<cv::Mat> RenderCloudViews(const std::vector<colmap_io::PlyPoint>& points, int size) {
  std::vector<cv::Mat> views(3);
  for (cv::Mat& view : views) view = cv::Mat(size, size, CV_8UC3, kBackground);
  const Cloud cloud = FinitePoints(points);
  if (cloud.xyz.empty()) return views;

  // The dense part's frame: the coordinate-wise median, and the principal
  // axes of the sampled points nearest to it.
  const std::vector<Eigen::Vector3d> sample = Sample(cloud.xyz);
  Eigen::Vector3d centre;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> coordinate;
    for (const auto& x : sample) coordinate.push_back(x[k]);
    centre[k] = Percentile(&coordinate, 0.5);
  }
  std::vector<double> distances;
  for (const auto& x : sample) distances.push_back((x - centre).norm());
  const double core_radius = Percentile(&distances, kCoreShare);
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const auto& x : sample) {
    if ((x - centre).norm() <= core_radius) covariance += (x - centre) * (x - centre).transpose();
  }
  // Eigenvalues ascending: axis 0 is the thinnest direction (the view "from
  // above" for a scene on the ground).
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  const Eigen::Matrix3d axes = solver.eigenvectors();

  for (int v = 0; v < 3; ++v) {
    // Looking along axis v; the picture spans the other two.
    const Eigen::Vector3d depth_axis = axes.col(v);
    const Eigen::Vector3d u_axis = axes.col((v + 2) % 3), w_axis = axes.col((v + 1) % 3);
    std::vector<double> us, ws;
    for (const auto& x : sample) {
      us.push_back((x - centre).dot(u_axis));
      ws.push_back((x - centre).dot(w_axis));
    }
    const double u_low = Percentile(&us, kLowPercentile), u_high = Percentile(&us, kHighPercentile);
    const double w_low = Percentile(&ws, kLowPercentile), w_high = Percentile(&ws, kHighPercentile);
    const double extent = std::max({u_high - u_low, w_high - w_low, 1e-12});
    const double scale = kFill * size / extent;
    const double u_centre = 0.5 * (u_low + u_high), w_centre = 0.5 * (w_low + w_high);
    std::vector<std::size_t> inside;
    std::vector<double> cols, rows;
    for (std::size_t i = 0; i < cloud.xyz.size(); ++i) {
      const Eigen::Vector3d d = cloud.xyz[i] - centre;
      const double col = 0.5 * size + (d.dot(u_axis) - u_centre) * scale;
      const double row = 0.5 * size - (d.dot(w_axis) - w_centre) * scale;
      if (col < -0.5 || row < -0.5 || col > size - 0.5 || row > size - 0.5) continue;
      inside.push_back(i);
      cols.push_back(col);
      rows.push_back(row);
    }
    Canvas canvas(size, size);
    const int radius = SplatRadius(inside.size(), static_cast<double>(size) * size);
    for (std::size_t j = 0; j < inside.size(); ++j) {
      const std::size_t i = inside[j];
      canvas.Splat(rows[j], cols[j], (cloud.xyz[i] - centre).dot(depth_axis), radius, cloud.bgr[i]);
    }
    canvas.CloseHoles();
    views[static_cast<std::size_t>(v)] = canvas.image;
  }
  return views;
}

cv::Mat RenderCloudFromCamera(const std::vector<colmap_io::PlyPoint>& points,
                              const CloudCamera& camera, int width) {
  if (camera.width < 1 || camera.height < 1 || width < 1) {
    throw std::invalid_argument("RenderCloudFromCamera: a camera of " + std::to_string(camera.width) +
                                "x" + std::to_string(camera.height) + " pixels drawn " +
                                std::to_string(width) + " pixels wide");
  }
  const double scale = static_cast<double>(width) / camera.width;
  const int height = std::max(1, static_cast<int>(std::lround(camera.height * scale)));
  // COLMAP's pixel convention: the top-left pixel's centre is at (0.5, 0.5),
  // so scaling the picture scales those coordinates.
  const Cloud cloud = FinitePoints(points);
  std::vector<std::size_t> inside;
  std::vector<double> cols, rows, zs;
  for (std::size_t i = 0; i < cloud.xyz.size(); ++i) {
    const Eigen::Vector3d x = camera.K * (camera.R * cloud.xyz[i] + camera.t);
    if (!(x.z() > 0)) continue;
    const double col = x.x() / x.z() * scale - 0.5, row = x.y() / x.z() * scale - 0.5;
    if (col < -0.5 || row < -0.5 || col > width - 0.5 || row > height - 0.5) continue;
    inside.push_back(i);
    cols.push_back(col);
    rows.push_back(row);
    zs.push_back(x.z());
  }
  Canvas canvas(height, width);
  const int radius = SplatRadius(inside.size(), static_cast<double>(width) * height);
  for (std::size_t j = 0; j < inside.size(); ++j) {
    canvas.Splat(rows[j], cols[j], zs[j], radius, cloud.bgr[inside[j]]);
  }
  canvas.CloseHoles();
  return canvas.image;
}

}  // namespace dispmvs::eval
