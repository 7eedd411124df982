#pragma once
// Large synthetic COLMAP dense workspaces with exact maps, for measuring how
// planning, the geometric filter and fusion of dispmvs_colmap scale with the
// number of images (bench/scale_bench.sh). The network is not involved: the
// photometric maps are the exact geometry, as if it had been perfect, so
// `dispmvs_colmap --mode plan` and `--mode fuse` run on them directly.
//
// The scene is the ground plane z = 0 with a procedural texture of the world
// position (views agree in colour). One PINHOLE camera flies over it on a
// grid, `images_per_row` images per row along +x, rows stepping along +y, at
// `altitude` above the plane, looking down with a forward tilt towards +y so
// that depth changes from the top rows of an image to the bottom ones. The
// grid spacing makes neighbouring footprints overlap by `overlap` along both
// axes.
//
// Written like `colmap image_undistorter` would (no patch-match.cfg, no
// fusion.cfg: every image is a reference with `__auto__` sources):
//
//   DIR/images/img_00000.png ...        the rendered views
//   DIR/sparse/{cameras,images,points3D}.bin
//   DIR/stereo/{depth,normal,confidence}_maps/NAME.dispmvs.photometric.bin
//
// Maps follow COLMAP's dense indexing (docs/dense.md, "Conventions"): depth
// pixel (col, row) is the camera z of the ray K^-1 (col, row, 1) where it
// meets the plane, normals are the plane's normal in the camera frame
// (facing the camera), confidence is 1 where there is a depth. The sparse
// points lie on the plane, each observed at its exact projection by every
// image whose frame holds it; only points seen by two images or more are
// kept (as SfM keeps only triangulated points).
//
// Time and memory are linear in the number of images: one view is rendered
// at a time, and the images observing a point are found through a grid of
// ground cells, not by testing every image.

#include <cstdint>
#include <filesystem>
#include <ostream>

namespace dispmvs::bench {

struct LargeWorkspaceOptions {
  int num_images = 200;
  int width = 160;
  int height = 120;
  // Sparse-point density: an image observes about this many points (before
  // dropping points seen by one image only, at the corners of the grid).
  int points_per_image = 100;
  uint64_t seed = 1;
  int images_per_row = 20;
  // Focal length as a multiple of the width (both fx and fy).
  double focal_per_width = 0.8;
  double altitude = 10.0;
  double tilt_deg = 15.0;  // optical axis turned from the nadir towards +y
  double overlap = 0.7;    // share of a footprint's extent shared by neighbours

  // Throws std::invalid_argument naming the offending field.
  void Check() const;
};

struct LargeWorkspaceSummary {
  int num_images = 0;
  int num_rows = 0;
  double spacing_x = 0.0, spacing_y = 0.0;  // grid steps on the ground
  // Triangulation angle at the footprint centre between an image and its
  // right-hand neighbour and its neighbour in the next row, degrees.
  double neighbour_angle_x_deg = 0.0, neighbour_angle_y_deg = 0.0;
  double depth_min = 0.0, depth_max = 0.0;  // over the maps' pixels
  uint64_t num_points3D = 0;
  uint64_t num_observations = 0;
};

// Writes the workspace into `dir` (created; files of the same names are
// replaced, each atomically). Progress lines go to `log` every few hundred
// images. Throws std::invalid_argument for bad options, IoError on I/O errors.
LargeWorkspaceSummary WriteLargeWorkspace(const std::filesystem::path& dir,
                                          const LargeWorkspaceOptions& options, std::ostream& log);

}  // namespace dispmvs::bench
