#include "dense/fusion_pass.h"

#include <algorithm>
#include <cstdint>
#include <memory>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"
#include "colmap_io/image_io.h"
#include "colmap_io/stereo_config.h"
#include "dense/geometric_pass.h"
#include "dense/pass_summary.h"
#include "dense/workspace_maps.h"
#include "fusion/fused_cloud_writer.h"
#include "fusion/point_fusion.h"
#include "fusion/view_cache.h"

namespace dispmvs::dense {

namespace fs = std::filesystem;
using namespace colmap_io;

std::vector<image_t> FusionImageOrder(const Workspace& workspace, const DensePlan& plan) {
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
  return image_ids;
}

std::optional<ViewClaim> ClaimGeometricAndFusion(const Workspace& workspace,
                                                  const DensePlan& plan, const fs::path& ply_path,
                                                  const std::vector<fs::path>& other_outputs,
                                                  std::ostream& log, long* holder_pid) {
  std::optional<ViewClaim> claim = ViewClaim::TryClaim(FusionClaimPath(workspace), holder_pid);
  if (!claim) return claim;
  int removed = RemoveGeometricLeftovers(workspace, plan) +
                fusion::FusedCloudWriter::RemoveLeftovers(ply_path);
  for (const fs::path& output : other_outputs) removed += RemoveLeftoverTemporaries(output);
  if (removed > 0) {
    log << "fuse: removed " << removed
        << " temporary file(s) that an interrupted run had left beside its outputs\n";
  }
  return claim;
}

FusionSummary RunFusion(const Workspace& workspace, const DensePlan& plan,
                        const fusion::FusionOptions& options, const fs::path& ply_path,
                        std::ostream& log, std::size_t max_cache_bytes, const ImageMasks& masks) {
  options.Check();
  const auto start = Clock::now();
  const std::vector<image_t> image_ids = FusionImageOrder(workspace, plan);
  std::map<image_t, const StereoProblem*> problem_of;
  for (const StereoProblem& problem : plan.problems) problem_of[problem.reference_image_id] = &problem;
  std::map<image_t, uint32_t> dense_index;
  const std::vector<image_t> order = plan.model.DenseImageOrder();
  for (std::size_t i = 0; i < order.size(); ++i) dense_index[order[i]] = static_cast<uint32_t>(i);

  // The views: the listed images with a depth map, once each, in order. Only
  // their names are held here; their maps are read when fusion needs them.
  std::vector<image_t> view_images;
  std::map<image_t, int> view_of;
  for (image_t image_id : image_ids) {
    if (view_of.count(image_id) > 0 ||
        !fs::is_regular_file(PathsOf(workspace, plan.ImageOf(image_id).name, kPhotometricType).depth)) {
      continue;
    }
    view_of[image_id] = static_cast<int>(view_images.size());
    view_images.push_back(image_id);
  }
  // Each view's sources, known from the plan before any map is read, so
  // that fusion can free what it keeps per view after the view's last use.
  std::vector<std::vector<int>> sources_of(view_images.size());
  for (std::size_t v = 0; v < view_images.size(); ++v) {
    const auto problem = problem_of.find(view_images[v]);
    if (problem == problem_of.end()) continue;
    for (image_t source : problem->second->source_image_ids) {
      const auto source_view = view_of.find(source);
      if (source_view != view_of.end()) sources_of[v].push_back(source_view->second);
    }
  }
  std::vector<bool> usable(view_images.size(), false);
  std::size_t pixels = 0, masked_pixels = 0;
  auto load = [&](int index) -> std::shared_ptr<const fusion::FusionView> {
    const image_t image_id = view_images[static_cast<std::size_t>(index)];
    const std::string& name = plan.ImageOf(image_id).name;
    try {
      auto view = std::make_shared<fusion::FusionView>();
      view->geometry = LoadDepthView(workspace, plan, image_id, kPhotometricType);
      const std::size_t ignored = masks.Apply(name, &view->geometry);
      view->normals = ReadNormalsMatching(PathsOf(workspace, name, kPhotometricType).normal,
                                          view->geometry.depth);
      const ResizedImage full = ReadFullImage(workspace, plan, image_id);
      view->image = ResampleToDenseIndexGrid(full.image, full.K,
                                             cv::Size(view->geometry.depth.width(),
                                                      view->geometry.depth.height()))
                        .image;
      view->vis_index = dense_index.at(image_id);
      const auto lowered = plan.min_consistent_views.find(image_id);
      if (lowered != plan.min_consistent_views.end()) {
        view->min_consistent_views = lowered->second;
      }
      view->source_views = sources_of[static_cast<std::size_t>(index)];
      if (!usable[static_cast<std::size_t>(index)]) {  // counted at the first load only
        pixels += view->geometry.depth.size();
        masked_pixels += ignored;
      }
      usable[static_cast<std::size_t>(index)] = true;
      return view;
    } catch (const std::exception& error) {
      log << "fusion: " << name << ": left out: " << error.what() << '\n';
      return nullptr;
    }
  };
  fusion::FusionViewCache cache(load, max_cache_bytes);
  // Points go to disk as they are made: memory does not grow with them.
  fusion::FusedCloudWriter writer(ply_path);
  fusion::FusePoints(static_cast<int>(view_images.size()), &cache, options,
                     [&writer](fusion::FusedPoint&& point) { writer.Add(point); }, nullptr,
                     fusion::LastUses(sources_of));
  writer.Finish();
  FusionSummary summary;
  summary.num_points = writer.size();
  summary.num_images = static_cast<int>(std::count(usable.begin(), usable.end(), true));
  summary.map_loads = cache.loads();
  summary.peak_cache_bytes = cache.peak_bytes();
  summary.pixels = pixels;
  summary.masked_pixels = masked_pixels;
  summary.seconds = SecondsSince(start);
  log << "fusion: " << summary.num_points << " points from " << summary.num_images << " image(s) -> "
      << ply_path.string() << " (+ .vis), " << FormatSeconds(summary.seconds) << "; "
      << summary.map_loads << " map loads, at most " << FormatMegabytes(summary.peak_cache_bytes)
      << " of maps held (--fusion_cache_mb " << max_cache_bytes / (1024 * 1024) << ")\n"
      << std::flush;
  return summary;
}

}  // namespace dispmvs::dense
