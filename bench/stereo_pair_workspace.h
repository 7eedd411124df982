#pragma once
// A rectified stereo pair with ground-truth disparity (Middlebury 2014
// conventions) as a COLMAP dense workspace with ground truth, so that
// dispmvs_colmap and dispmvs_eval run on real images:
//
//   DIR/images/left.EXT, right.EXT       the input files, byte for byte
//   DIR/sparse/{cameras,images,points3D}.bin
//        camera 1 (left):  PINHOLE f, f, cx, cy
//        camera 2 (right): PINHOLE f, f, cx + doffs, cy
//        image 1 left.EXT at the origin, image 2 right.EXT with centre
//        (baseline, 0, 0), identity rotations (COLMAP world-to-camera
//        t = -R C = (-baseline, 0, 0)); world units are the baseline's
//        sparse points: two-view tracks from the GT disparity (see below)
//   DIR/stereo/patch-match.cfg           each image with the other as source
//   DIR/stereo/fusion.cfg                both images
//   DIR/stereo/{depth,normal,confidence}_maps/, consistency_graphs/ (empty)
//   DIR/ground_truth/depth_maps/left.EXT.bin   GT depth of the left image
//   DIR/ground_truth/README.txt          the calibration and conventions
//
// Conventions. The calibration is taken in COLMAP's convention (the centre of
// the top-left pixel at (0.5, 0.5)). The disparity map holds, for the centre
// of left pixel (col, row), the disparity d with x_right = x_left - d; depth
// is z = baseline * f / (d + doffs). A disparity is valid when finite and
// d + doffs > 0. The GT depth map follows COLMAP's dense indexing (as
// synth/workspace_writer.h does): its pixel (col, row) is image position
// (col, row), the corner shared by left pixels (col - 1 .. col, row - 1 ..
// row). It holds the depth of the mean of those four disparities (bilinear
// interpolation, exact for planes) when all four are valid and differ by at
// most max_disparity_step (else the corner straddles a depth edge and has no
// GT); row 0 and column 0 have no GT.
//
// Sparse points stand in for SfM points, so that dispmvs_colmap derives its
// depth-range hint from them: a left pixel centre with valid disparity is
// the 3-D point at its depth, observed in both images at its exact
// projections, when it lands inside the right image and no left pixel whose
// disparity is larger by more than max_disparity_step lands on the same
// right-image pixel (so occluded points are not observed). Of those
// candidates, num_sparse_points are taken evenly spaced in raster order
// (deterministic).

#include <cstdint>
#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

#include "bench/npy_reader.h"
#include "colmap_io/dense_array.h"
#include "colmap_io/sparse_model.h"

namespace dispmvs::bench {

struct StereoPairCalibration {
  double focal = 0;     // pixels, both cameras
  double cx = 0;        // left camera, COLMAP convention
  double cy = 0;        // both cameras
  double doffs = 0;     // right cx - left cx
  double baseline = 0;  // the workspace's length unit (e.g. mm)

  // std::invalid_argument naming the field: focal and baseline must be
  // finite and > 0, the others finite.
  void Check() const;
  // Depth of disparity d; only meaningful for d + doffs > 0.
  double DepthOfDisparity(double disparity) const { return baseline * focal / (disparity + doffs); }
  bool IsValidDisparity(double disparity) const;
};

struct StereoPairWorkspaceOptions {
  std::filesystem::path left_image;
  std::filesystem::path right_image;
  StereoPairCalibration calibration;
  int num_sparse_points = 2000;      // in [1, 10000000]
  double max_disparity_step = 1.0;   // pixels, > 0 (inf: never split surfaces)

  void Check() const;  // std::invalid_argument naming the field
};

struct StereoPairWorkspaceSummary {
  int width = 0, height = 0;
  std::string left_name, right_name;
  int64_t valid_disparities = 0;   // of the disparity map
  int64_t gt_pixels = 0;           // GT depth pixels with a depth
  int64_t gt_dropped_at_edges = 0; // corners of four valid disparities that disagree
  double gt_min_depth = 0, gt_max_depth = 0;
  int64_t sparse_candidates = 0;   // valid, inside the right image, not occluded
  int64_t num_points3D = 0;
};

// The GT depth map of the left image from its disparity map (conventions
// above). `dropped_at_edges` (optional) receives the number of corners left
// empty because their four valid disparities differ by more than the step.
colmap_io::DenseArray DisparityToDenseDepth(const NpyMatrix& disparity,
                                            const StereoPairCalibration& calibration,
                                            double max_disparity_step,
                                            int64_t* dropped_at_edges = nullptr);

// The sparse model above (cameras, poses, points) for images of
// width x height named left_name and right_name. `rgb_left` (CV_32FC3 RGB in
// [0, 1], as colmap_io::ReadImageRgb returns) gives the points' colours.
// `candidates` (optional) receives the number of candidate pixels.
colmap_io::SparseModel BuildStereoPairModel(const NpyMatrix& disparity,
                                            const StereoPairCalibration& calibration,
                                            const std::string& left_name,
                                            const std::string& right_name,
                                            const cv::Mat& rgb_left, int num_sparse_points,
                                            double max_disparity_step,
                                            int64_t* candidates = nullptr);

// Writes the whole workspace into `dir` (created if needed; files of the same
// name are replaced). Throws std::invalid_argument for bad options and
// colmap_io::IoError naming the file at fault: an image that cannot be read,
// images of different sizes or a disparity map of another size than the
// left image, no valid disparity, no sparse point.
StereoPairWorkspaceSummary WriteStereoPairWorkspace(const std::filesystem::path& dir,
                                                    const NpyMatrix& disparity,
                                                    const std::filesystem::path& disparity_path,
                                                    const StereoPairWorkspaceOptions& options);

}  // namespace dispmvs::bench
