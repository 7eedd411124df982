#include "dense/workspace_maps.h"

#include <utility>

#include <opencv2/core.hpp>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"

namespace dispmvs::dense {

namespace fs = std::filesystem;
using namespace colmap_io;

namespace {

ProblemView MakeView(const ResizedImage& full, const Image& image, const cv::Size& size) {
  const ResizedImage grid = ResampleToDenseIndexGrid(full.image, full.K, size);
  ProblemView view;
  view.image_id = static_cast<int64_t>(image.image_id);
  view.image = grid.image;
  view.K = grid.K;
  view.R = image.RotationMatrix();
  view.t = image.tvec;
  return view;
}

// Camera geometry of an image's map of size `map_width` x `map_height`.
fusion::DepthView MapGeometry(const DensePlan& plan, image_t image_id, int map_width,
                              int map_height) {
  const Image& image = plan.ImageOf(image_id);
  const Camera& camera = plan.model.cameras.at(image.camera_id);
  fusion::DepthView view;
  view.K = ScaleIntrinsics(camera.CalibrationMatrix(),
                           cv::Size(static_cast<int>(camera.width), static_cast<int>(camera.height)),
                           cv::Size(map_width, map_height));
  view.R = image.RotationMatrix();
  view.t = image.tvec;
  return view;
}

}  // namespace

bool MapPaths::AllExist() const {
  return fs::is_regular_file(depth) && fs::is_regular_file(normal) &&
         fs::is_regular_file(confidence);
}

MapPaths PathsOf(const Workspace& workspace, const std::string& name, const std::string& type) {
  return {workspace.DepthMapPath(name, type), workspace.NormalMapPath(name, type),
          workspace.ConfidenceMapPath(name, type)};
}

void CheckMapFoldersWritable(const Workspace& workspace) {
  workspace.CreateStereoFolders();
  for (const fs::path& folder :
       {workspace.DepthMapsDir(), workspace.NormalMapsDir(), workspace.ConfidenceMapsDir()}) {
    try {
      AtomicFileWriter probe(folder / "dispmvs_write_probe");  // removed again, never committed
    } catch (const IoError&) {
      throw IoError(folder.string(), "cannot create files in this folder (read-only?)");
    }
  }
}

void WriteMaps(const MapPaths& paths, const DenseArray& depth, const DenseArray& normal,
               const DenseArray& confidence) {
  WriteDenseArray(confidence, paths.confidence);
  WriteDenseArray(normal, paths.normal);
  WriteDenseArray(depth, paths.depth);
}

ResizedImage ReadFullImage(const Workspace& workspace, const DensePlan& plan, image_t image_id) {
  const Image& image = plan.ImageOf(image_id);
  return ReadImageForCamera(workspace.ImagePath(image.name), plan.model.cameras.at(image.camera_id),
                            /*max_image_size=*/-1);
}

ProblemViews LoadProblemViews(const Workspace& workspace, const DensePlan& plan,
                              const StereoProblem& problem, int max_image_size) {
  const ResizedImage reference = ReadFullImage(workspace, plan, problem.reference_image_id);
  const cv::Size size = ComputeResizedSize(reference.image.size(), max_image_size);
  ProblemViews loaded;
  loaded.views.push_back(MakeView(reference, plan.ImageOf(problem.reference_image_id), size));
  for (image_t source : problem.source_image_ids) {
    try {
      loaded.views.push_back(
          MakeView(ReadFullImage(workspace, plan, source), plan.ImageOf(source), size));
    } catch (const IoError& error) {
      loaded.left_out.push_back({plan.ImageOf(source).name, error.what()});
    }
  }
  if (loaded.views.size() == 1) {
    std::string reasons;
    for (const ProblemViews::LeftOut& source : loaded.left_out) reasons += "; " + source.reason;
    throw IoError(workspace.ImagePath(plan.ImageOf(problem.reference_image_id).name).string(),
                  "none of its " + std::to_string(problem.source_image_ids.size()) +
                      " source image(s) can be read" + reasons);
  }
  return loaded;
}

fusion::DepthView LoadDepthView(const Workspace& workspace, const DensePlan& plan,
                                image_t image_id, const std::string& type) {
  const MapPaths paths = PathsOf(workspace, plan.ImageOf(image_id).name, type);
  DenseArray depth = ReadDenseArray(paths.depth);
  if (depth.channels() != 1) throw IoError(paths.depth.string(), "depth map must have 1 channel");
  fusion::DepthView view = MapGeometry(plan, image_id, depth.width(), depth.height());
  view.depth = std::move(depth);
  if (fs::is_regular_file(paths.confidence)) {
    view.confidence = ReadDenseArray(paths.confidence);
    if (view.confidence.width() != view.depth.width() ||
        view.confidence.height() != view.depth.height() || view.confidence.channels() != 1) {
      throw IoError(paths.confidence.string(), "confidence map does not match its depth map");
    }
  }
  return view;
}

DenseArray ReadNormalsMatching(const fs::path& path, const DenseArray& depth) {
  DenseArray normal = ReadDenseArray(path);
  if (normal.width() != depth.width() || normal.height() != depth.height() ||
      normal.channels() != 3) {
    throw IoError(path.string(), "normal map does not match its depth map");
  }
  return normal;
}

double ValidFraction(const DenseArray& depth) {
  if (depth.size() == 0) return 0;
  std::size_t valid = 0;
  for (float d : depth.values()) valid += d > 0 ? 1 : 0;
  return static_cast<double>(valid) / static_cast<double>(depth.size());
}

}  // namespace dispmvs::dense
