#pragma once
// Where the passes of dispmvs_colmap keep their maps in a workspace, and how
// they read images and maps back with the camera geometry that goes with
// them. Every pass goes through these, so that a map is always paired with
// the intrinsics of its own size and written the same way:
//
//   WS/stereo/depth_maps/NAME.TYPE.bin       depth (1 channel, 0 = none)
//   WS/stereo/normal_maps/NAME.TYPE.bin      normals (3 channels, camera frame)
//   WS/stereo/confidence_maps/NAME.TYPE.bin  confidence in [0, 1]
//
// with TYPE = dispmvs.photometric (the network's maps) or dispmvs.geometric
// (after the multi-view consistency filter), beside COLMAP's own
// NAME.photometric.bin / NAME.geometric.bin, which are never touched.

#include <filesystem>
#include <string>
#include <vector>

#include "colmap_io/dense_array.h"
#include "colmap_io/image_io.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/workspace.h"
#include "dense/depth_estimator.h"
#include "dense/plan.h"
#include "fusion/geometric_filter.h"

namespace dispmvs::dense {

inline constexpr const char* kPhotometricType = "dispmvs.photometric";
inline constexpr const char* kGeometricType = "dispmvs.geometric";

struct MapPaths {
  std::filesystem::path depth, normal, confidence;
  bool AllExist() const;
};

MapPaths PathsOf(const colmap_io::Workspace& workspace, const std::string& name,
                 const std::string& type);

// Creates the stereo folders and checks that a file can be created in each
// map folder; throws IoError naming the first that refuses (read-only, not a
// folder). Called before a pass does any work, so that it fails at once.
void CheckMapFoldersWritable(const colmap_io::Workspace& workspace);

// Each file through a temporary name; the depth map is written last, so its
// presence marks a complete view (what resuming relies on).
void WriteMaps(const MapPaths& paths, const colmap_io::DenseArray& depth,
               const colmap_io::DenseArray& normal, const colmap_io::DenseArray& confidence);

// The full-size image of `image_id`, checked against its camera (IoError when
// unreadable or of another size).
colmap_io::ResizedImage ReadFullImage(const colmap_io::Workspace& workspace,
                                      const DensePlan& plan, colmap_io::image_t image_id);

struct ProblemViews {
  std::vector<ProblemView> views;  // the reference first, then the sources read
  struct LeftOut {
    std::string name;    // the source image's
    std::string reason;  // the IoError's message, naming the file
  };
  std::vector<LeftOut> left_out;  // sources that could not be read: the view runs without them
};

// The reference at the --max_image_size size (<= 0: full size), its sources
// brought to the same size (per-axis scaled intrinsics keep them exact), each
// on COLMAP's dense index grid. A source image that cannot be read (missing,
// damaged, of the wrong size) is left out and listed, as the geometric pass
// and fusion leave out an unreadable map: one bad file costs its own view,
// not every view that would have used it. Throws IoError when the reference
// cannot be read, or when no source can (naming each and why).
ProblemViews LoadProblemViews(const colmap_io::Workspace& workspace, const DensePlan& plan,
                              const colmap_io::StereoProblem& problem, int max_image_size);

// The depth and (when present) confidence maps of `type` with the camera
// geometry of the map's own size; throws IoError on unreadable or
// inconsistent files.
fusion::DepthView LoadDepthView(const colmap_io::Workspace& workspace, const DensePlan& plan,
                                colmap_io::image_t image_id, const std::string& type);

// The normal map at `path`, which must have the size of `depth` and 3
// channels (IoError otherwise).
colmap_io::DenseArray ReadNormalsMatching(const std::filesystem::path& path,
                                          const colmap_io::DenseArray& depth);

// Share of pixels with a depth (> 0); 0 for an empty map.
double ValidFraction(const colmap_io::DenseArray& depth);

}  // namespace dispmvs::dense
