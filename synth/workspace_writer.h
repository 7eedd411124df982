#pragma once
// Writes generated samples (generator.h) to disk as complete COLMAP dense
// workspaces with exact ground truth, for training and for evaluating the
// whole COLMAP pipeline:
//
//   DIR/images/view_00.png ...           8-bit RGB, round(255 x generated value)
//   DIR/sparse/{cameras,images,points3D}.bin
//        one PINHOLE camera per view (COLMAP convention: cx = cx_index + 0.5),
//        exact metric poses, and sparse points sampled from each view's ground
//        truth (a jittered grid), observed at their exact projections by every
//        view whose ground truth agrees (visibility)
//   DIR/stereo/patch-match.cfg           "__auto__, V-1" for every image
//   DIR/stereo/fusion.cfg                every image
//   DIR/stereo/{depth,normal,confidence}_maps/, consistency_graphs/ (empty)
//   DIR/ground_truth/depth_maps/NAME.bin dense arrays: camera z, 0 = no surface
//   DIR/ground_truth/normal_maps/NAME.bin dense arrays: camera-frame unit normals
//        facing the camera (COLMAP's convention), 0 = no surface
//   DIR/ground_truth/points.ply          world points with normals and colours
//   DIR/ground_truth/README.txt          the sampling convention, rig and scale
//
// Ground-truth sampling: depth pixel (col, row) holds the ray through image
// position (col, row) in COLMAP's convention, i.e. pixel index (col - 0.5,
// row - 0.5): the indexing COLMAP's PatchMatch and stereo_fusion use (see
// colmap_io/image_io.h), so fusing the ground truth with colmap reproduces the
// surfaces exactly. The images themselves are rendered at pixel centres.
//
// Output is a deterministic function of (options, seed).

#include <cstdint>
#include <filesystem>
#include <ostream>
#include <string>

#include "synth/generator.h"

namespace dispmvs::synth {

struct SynthWorkspaceOptions {
  SynthConfig config;
  // Sparse points drawn per view (one per cell of a grid of about this many
  // cells, at a random pixel inside the cell); fewer survive (sky, no second
  // view).
  int sparse_points_per_view = 300;
  // A view observes a sparse point when the bilinear interpolation of its
  // ground-truth depth at the projection agrees with the point's depth within
  // this relative tolerance (so occluded points and points near depth edges
  // are not observed).
  double visibility_tolerance = 5e-5;
  // ground_truth/points.ply holds every ply_stride-th sample in each direction
  // of every view's ground truth.
  int ply_stride = 2;

  // Throws std::invalid_argument for values out of range (and config.Check()).
  void Check() const;
};

struct SynthWorkspaceSummary {
  std::size_t num_images = 0;
  std::size_t num_points3D = 0;
  std::size_t num_observations = 0;
  std::size_t num_ground_truth_points = 0;
  std::string rig;
  double scale = 1;
};

// The config with only `rig` enabled ("table", "walkthrough", "turntable",
// "outdoor"), or unchanged for "random". std::invalid_argument otherwise.
SynthConfig ConfigForRig(const std::string& rig, SynthConfig config);

// The generator seed of scene `scene_index` of a data set: a mix of both, so
// that data sets with neighbouring base seeds share no scenes.
uint64_t SceneSeed(uint64_t base_seed, int scene_index);

// "scene_000", "scene_001", ... (more digits past 999).
std::string SceneFolderName(int scene_index);

// Renders the sample of `seed` on the CPU and writes the workspace above into
// `dir` (created if needed; files of the same name are replaced). Throws
// std::invalid_argument for bad options, colmap_io::IoError naming a file that
// could not be written.
SynthWorkspaceSummary WriteSynthWorkspace(const std::filesystem::path& dir,
                                          const SynthWorkspaceOptions& options, uint64_t seed);

struct SynthDatasetSummary {
  int written = 0;
  int skipped = 0;  // already complete from an earlier run
};

// Writes scenes 0 .. num_scenes-1 (seed SceneSeed(base_seed, i)) into
// output_dir/SceneFolderName(i). Each is written to "<name>.tmp" (removed
// first if an interrupted run left one) and renamed when complete, so an
// existing scene folder is complete and is skipped. Progress lines go to `log`
// if given. num_scenes must be in [1, 1000000] (std::invalid_argument).
SynthDatasetSummary WriteSynthDataset(const std::filesystem::path& output_dir, int num_scenes,
                                      uint64_t base_seed, const SynthWorkspaceOptions& options,
                                      std::ostream* log = nullptr);

}  // namespace dispmvs::synth
