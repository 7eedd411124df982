#pragma once
// Writes the example dense workspace: what `colmap image_undistorter` would
// produce for a synthetic scene (examples/example_scene.h) photographed by
// seven PINHOLE cameras on an arc, plus the exact ground truth:
//
//   DIR/images/view_00.png ... view_06.png   320 x 240, 8-bit RGB
//   DIR/sparse/{cameras,images,points3D}.bin   exact poses; sparse points
//        sampled on the surfaces, observed (at their exact projections) by
//        every view that sees them unoccluded
//   DIR/stereo/patch-match.cfg                 "__auto__, 4" for every image
//   DIR/stereo/fusion.cfg                      every image
//   DIR/stereo/{depth,normal,confidence}_maps/, consistency_graphs/ (empty)
//   DIR/ground_truth/depth_maps/NAME.bin       dense arrays (dense_array.h),
//        the z depth along each pixel's ray, 0 where the ray hits nothing
//   DIR/ground_truth/normal_maps/NAME.bin      unit normals, camera frame,
//        pointing towards the camera (COLMAP's convention)
//   DIR/ground_truth/README.txt                what the above are, and which
//        sampling (below) they use
//
// NAME is the image name, e.g. view_00.png. Which ray a ground-truth pixel
// (col, row) holds is a choice (GroundTruthSampling): the pixel's centre
// (col + 0.5, row + 0.5) in the sparse model's convention, exact for the
// images; or (col, row), the indexing COLMAP's dense stage (PatchMatch,
// stereo_fusion) uses for its depth maps (see image_io.h).
// A sparse point is only observed where it and the four samples around its
// projection lie on the same face, so that interpolating the ground-truth
// depth map at an observation is exact (inverse depth is affine in the image
// position across a planar face).
//
// The output is a deterministic function of the seed, which changes the
// texture and the sparse point sample; the camera geometry is fixed.

#include <cstddef>
#include <cstdint>
#include <filesystem>

namespace dispmvs::examples {

enum class GroundTruthSampling {
  kPixelCentres,        // pixel (col, row) holds the ray through (col + 0.5, row + 0.5)
  kColmapDenseIndexing, // pixel (col, row) holds the ray through (col, row)
};

struct ExampleWorkspaceOptions {
  uint64_t seed = 0;
  GroundTruthSampling sampling = GroundTruthSampling::kPixelCentres;
};

struct ExampleWorkspaceSummary {
  std::size_t num_images = 0;
  std::size_t num_points3D = 0;
  std::size_t num_observations = 0;
};

// Creates `dir` if needed and writes the files above (files of the same name
// are replaced; nothing else in `dir` is touched). Throws
// colmap_io::IoError naming the file that could not be written.
ExampleWorkspaceSummary WriteExampleWorkspace(const std::filesystem::path& dir,
                                              const ExampleWorkspaceOptions& options = {});

}  // namespace dispmvs::examples
