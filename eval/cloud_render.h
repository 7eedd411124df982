#pragma once
// Pictures of a point cloud without a viewer: orthographic views along the
// cloud's principal axes, each point drawn in its own colour as a small
// square, the nearest point winning (a z-buffer). For the run report.

#include <vector>

#include <opencv2/core.hpp>

#include "colmap_io/ply.h"

namespace dispmvs::eval {

// Three CV_8UC3 (BGR) images of `size` x `size` pixels: the cloud seen along
// its least, middle and largest principal axis (top, front, side for a
// scene spread along the ground), scaled to fit with a margin, on a dark
// background. Non-finite points are skipped; an empty cloud gives blank
// images.
std::vector<cv::Mat> RenderCloudViews(const std::vector<colmap_io::PlyPoint>& points, int size);

}  // namespace dispmvs::eval
