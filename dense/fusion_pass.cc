#include "dense/fusion_pass.h"

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "colmap_io/error.h"
#include "colmap_io/image_io.h"
#include "colmap_io/stereo_config.h"
#include "dense/pass_summary.h"
#include "dense/workspace_maps.h"
#include "fusion/point_fusion.h"
#include "fusion/vis_file.h"

namespace dispmvs::dense {

namespace fs = std::filesystem;
using namespace colmap_io;

FusionSummary RunFusion(const Workspace& workspace, const DensePlan& plan,
                        const fusion::GeometricFilterOptions& options, const fs::path& ply_path,
                        std::ostream& log) {
  options.Check();
  const auto start = Clock::now();
  // Which images, in which order.
  std::vector<image_t> image_ids;
  if (fs::is_regular_file(workspace.FusionConfigPath())) {
    for (const std::string& name : ReadFusionConfig(workspace.FusionConfigPath())) {
      const Image* image = plan.model.FindImageByName(name);
      if (image == nullptr) {
        throw IoError(workspace.FusionConfigPath().string(),
                      "image \"" + name + "\" is not in the sparse model");
      }
      image_ids.push_back(image->image_id);
    }
  } else {
    for (const StereoProblem& problem : plan.problems) image_ids.push_back(problem.reference_image_id);
  }
  std::map<image_t, const StereoProblem*> problem_of;
  for (const StereoProblem& problem : plan.problems) problem_of[problem.reference_image_id] = &problem;
  std::map<image_t, uint32_t> dense_index;
  const std::vector<image_t> order = plan.model.DenseImageOrder();
  for (std::size_t i = 0; i < order.size(); ++i) dense_index[order[i]] = static_cast<uint32_t>(i);

  std::vector<fusion::FusionView> views;
  std::map<image_t, int> view_of;
  for (image_t image_id : image_ids) {
    const std::string& name = plan.ImageOf(image_id).name;
    const MapPaths paths = PathsOf(workspace, name, kPhotometricType);
    if (view_of.count(image_id) > 0 || !fs::is_regular_file(paths.depth)) continue;
    try {
      fusion::FusionView view;
      view.geometry = LoadDepthView(workspace, plan, image_id, kPhotometricType);
      view.normals = ReadNormalsMatching(paths.normal, view.geometry.depth);
      const ResizedImage full = ReadFullImage(workspace, plan, image_id);
      view.image = ResampleToDenseIndexGrid(full.image, full.K,
                                            cv::Size(view.geometry.depth.width(),
                                                     view.geometry.depth.height()))
                       .image;
      view.vis_index = dense_index.at(image_id);
      const auto lowered = plan.min_consistent_views.find(image_id);
      if (lowered != plan.min_consistent_views.end()) {
        view.min_consistent_views = lowered->second;
      }
      view_of[image_id] = static_cast<int>(views.size());
      views.push_back(std::move(view));
    } catch (const std::exception& error) {
      log << "fusion: " << name << ": left out: " << error.what() << '\n';
    }
  }
  for (const auto& [image_id, index] : view_of) {
    const auto problem = problem_of.find(image_id);
    if (problem == problem_of.end()) continue;
    for (image_t source : problem->second->source_image_ids) {
      const auto source_view = view_of.find(source);
      if (source_view != view_of.end()) views[index].source_views.push_back(source_view->second);
    }
  }
  const std::vector<fusion::FusedPoint> points = fusion::FusePoints(views, options);
  fusion::WriteFusedPointCloud(points, ply_path);
  FusionSummary summary;
  summary.num_points = points.size();
  summary.num_images = static_cast<int>(views.size());
  summary.seconds = SecondsSince(start);
  log << "fusion: " << points.size() << " points from " << views.size() << " image(s) -> "
      << ply_path.string() << " (+ .vis), " << FormatSeconds(summary.seconds) << '\n'
      << std::flush;
  return summary;
}

}  // namespace dispmvs::dense
