#pragma once
// Pictures of a point cloud without a viewer, for the run report: views along
// the principal axes of the cloud's dense part, and the view from a camera.
// Each point is drawn in its own colour as a square whose size follows the
// density of the points in the picture, so that a dense cloud reads as
// surfaces and a sparse one still shows; the nearest point wins (a z-buffer).
//
// A real capture's cloud holds a few far points (sky, stray matches) that set
// any extent taken from all points and shrink the scene into a few pixels:
// the frame, the axes and the extent come from the dense part instead (the
// median centre, the covariance of the nearest 95 % of the points, the 1st
// to 99th percentiles of each picture's coordinates), and points outside
// the extent are left out of the picture.

#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "colmap_io/ply.h"

namespace dispmvs::eval {

// Three CV_8UC3 (BGR) images of `size` x `size` pixels: the cloud seen along
// the least, middle and largest principal axis of its dense part (top, front,
// side for a scene spread along the ground), scaled so that the 1st to 99th
// percentiles of its coordinates fill the picture with a margin, on a dark
// background. Non-finite points are skipped; an empty cloud gives blank
// images.
std::vector<cv::Mat> RenderCloudViews(const std::vector<colmap_io::PlyPoint>& points, int size);

// A pinhole camera of width x height pixels: a world point X is seen at
// x = K (R X + t), image coordinates (x0 / x2, x1 / x2) in COLMAP's
// convention (the top-left pixel's centre at (0.5, 0.5)).
struct CloudCamera {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world to camera
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  int width = 0;
  int height = 0;
};

// The cloud seen from `camera`, drawn at `width` pixels across (the camera's
// aspect ratio kept; K scaled with it): CV_8UC3 (BGR), points behind the
// camera or outside the picture left out. Throws std::invalid_argument for a
// camera without pixels or a width < 1.
cv::Mat RenderCloudFromCamera(const std::vector<colmap_io::PlyPoint>& points,
                              const CloudCamera& camera, int width);

}  // namespace dispmvs::eval
