#pragma once
// Test-only: a scene of two planes rendered analytically (ray casting with
// Eigen, independent of the code under test) into pinhole views, so that the
// filter and fusion tests know the exact depth, normal, colour and visibility
// of every pixel.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "colmap_io/dense_array.h"
#include "fusion/geometric_filter.h"

namespace dispmvs::fusion::testing {

struct Camera {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world-to-camera
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  int width = 0;
  int height = 0;

  Eigen::Vector3d Centre() const { return -R.transpose() * t; }
};

// A camera at `centre` looking at `target` (camera y roughly along world +y),
// with focal lengths fx, fy and principal point (cx, cy).
Camera LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target, int width, int height,
              double fx, double fy, double cx, double cy);

struct Plane {
  Eigen::Vector3d point;
  Eigen::Vector3d normal;  // unit, pointing towards the cameras (world -z side)
  // World x/y bounds of the part that exists (infinite when unbounded).
  double x_min, x_max, y_min, y_max;
  std::array<uint8_t, 3> rgb;

  double SignedDistance(const Eigen::Vector3d& x) const { return normal.dot(x - point); }
};

struct Hit {
  int plane = -1;  // -1: nothing hit
  double depth = 0.0;  // camera z
  Eigen::Vector3d world = Eigen::Vector3d::Zero();
};

// How a world point appears in a view, judged with a +-1 pixel margin so that
// rounding to the nearest pixel cannot change the verdict of a decided case.
enum class Visibility { kVisible, kHidden, kUndecided };

class Scene {
 public:
  // A slanted unbounded background plane (depth ~10) and a slanted bounded
  // rectangle in front of it (depth ~5) that occludes part of it.
  static Scene TwoPlanes();

  const std::vector<Plane>& planes() const { return planes_; }

  // The nearest plane along the ray through (col, row) (raw pixel indices).
  Hit RayCast(const Camera& camera, double col, double row) const;

  // 1-channel depth (0 where nothing is hit).
  colmap_io::DenseArray RenderDepth(const Camera& camera) const;
  // 3-channel camera-frame normals, towards the camera.
  colmap_io::DenseArray RenderNormals(const Camera& camera) const;
  // RGB image of the plane colours, CV_8UC3 or CV_32FC3 (value / 255).
  cv::Mat RenderImage(const Camera& camera, int type) const;

  // kVisible: the projection of `x` (on plane `plane`) and its 8 neighbours
  // at +-1 pixel all lie in the image and all see that plane. kHidden: all 9
  // are outside the image, see another plane or nothing, or x is behind the
  // camera. Else kUndecided.
  Visibility Classify(const Camera& camera, const Eigen::Vector3d& x, int plane) const;

 private:
  std::vector<Plane> planes_;
};

// The scene's default views: an 80 x 60 rig of `count` (<= 4) cameras with
// non-square pixels and an off-centre principal point, all looking at the
// background plane.
std::vector<Camera> DefaultCameras(int count);

DepthView MakeDepthView(const Camera& camera, const colmap_io::DenseArray& depth);

}  // namespace dispmvs::fusion::testing
