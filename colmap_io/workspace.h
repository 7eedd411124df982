#pragma once
// A COLMAP dense workspace, the folder `colmap image_undistorter` writes:
//
//   ROOT/images/...                      undistorted images (names may contain '/')
//   ROOT/sparse/                         cameras, images, points3D (.bin or .txt)
//   ROOT/stereo/patch-match.cfg, fusion.cfg
//   ROOT/stereo/depth_maps/NAME.TYPE.bin
//   ROOT/stereo/normal_maps/NAME.TYPE.bin
//   ROOT/stereo/confidence_maps/NAME.TYPE.bin
//   ROOT/stereo/consistency_graphs/NAME.TYPE.bin
//
// TYPE is COLMAP's "photometric" / "geometric", or an estimator-qualified name
// such as "dispmvs.photometric" (see docs/colmap-layout.md). This class only
// knows where things are; reading and writing is done by sparse_model_io.h,
// dense_array.h and stereo_config.h.

#include <filesystem>
#include <string>

#include "colmap_io/sparse_model.h"

namespace dispmvs::colmap_io {

class Workspace {
 public:
  // Checks the layout: `root` must be a directory holding an images/ and a
  // sparse/ directory. stereo/ may be missing (CreateStereoFolders() makes it).
  // Throws IoError naming the missing or wrong path.
  explicit Workspace(const std::filesystem::path& root);

  const std::filesystem::path& root() const { return root_; }
  std::filesystem::path ImagesDir() const { return root_ / "images"; }
  std::filesystem::path SparseDir() const { return root_ / "sparse"; }
  std::filesystem::path StereoDir() const { return root_ / "stereo"; }
  std::filesystem::path DepthMapsDir() const { return StereoDir() / "depth_maps"; }
  std::filesystem::path NormalMapsDir() const { return StereoDir() / "normal_maps"; }
  std::filesystem::path ConfidenceMapsDir() const { return StereoDir() / "confidence_maps"; }
  std::filesystem::path ConsistencyGraphsDir() const {
    return StereoDir() / "consistency_graphs";
  }
  std::filesystem::path PatchMatchConfigPath() const { return StereoDir() / "patch-match.cfg"; }
  std::filesystem::path FusionConfigPath() const { return StereoDir() / "fusion.cfg"; }

  // ReadSparseModel(SparseDir()): binary or text, validated.
  SparseModel ReadModel() const;

  // ROOT/images/NAME. Every per-image path below throws IoError naming the
  // workspace when NAME could point outside it (empty, absolute, or with a
  // "." / ".." component, or a backslash, which COLMAP never writes): image
  // names come from a file and become paths we write to.
  std::filesystem::path ImagePath(const std::string& image_name) const;
  // stereo/depth_maps/NAME.TYPE.bin and friends. TYPE must be non-empty and
  // free of '/' and '\'. Sub-folders of NAME are not created here: writers
  // create parent directories (atomic_file.h).
  std::filesystem::path DepthMapPath(const std::string& image_name, const std::string& type) const;
  std::filesystem::path NormalMapPath(const std::string& image_name,
                                      const std::string& type) const;
  std::filesystem::path ConfidenceMapPath(const std::string& image_name,
                                          const std::string& type) const;
  std::filesystem::path ConsistencyGraphPath(const std::string& image_name,
                                             const std::string& type) const;

  // Creates stereo/ and its four map folders (existing ones are kept).
  // Throws IoError naming the folder that could not be created.
  void CreateStereoFolders() const;

 private:
  std::filesystem::path MapPath(const std::filesystem::path& folder, const std::string& image_name,
                                const std::string& type) const;

  std::filesystem::path root_;
};

}  // namespace dispmvs::colmap_io
