#include "eval/workspace_eval.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <stdexcept>
#include <system_error>
#include <utility>

#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "colmap_io/view_record.h"
#include "eval/depth_png.h"

namespace dispmvs::eval {
namespace {

namespace fs = std::filesystem;
using colmap_io::IoError;

std::string SizeText(uint64_t width, uint64_t height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

colmap_io::DenseArray ReadDepthMap(const fs::path& path, const char* what) {
  colmap_io::DenseArray map = colmap_io::ReadDenseArray(path);
  if (map.channels() != 1) {
    throw IoError(path.string(), std::string(what) + " has " + std::to_string(map.channels()) +
                                     " channels, a depth map has 1");
  }
  return map;
}

bool IsFile(const fs::path& path) {
  std::error_code ec;
  return fs::is_regular_file(path, ec);
}

// The same relative layout as the maps: DIR/NAME.SUFFIX.
fs::path PngPath(const std::string& dir, const std::string& image_name, const std::string& suffix) {
  return fs::path(dir) / (image_name + "." + suffix + ".png");
}

}  // namespace

void WorkspaceEvalOptions::Check() const {
  for (const std::string& type : types) {
    if (type.empty() || type.find('/') != std::string::npos ||
        type.find('\\') != std::string::npos) {
      throw std::invalid_argument("invalid depth-map type \"" + type + "\"");
    }
  }
  const auto check_distance = [](double value, const char* name) {
    if (!(std::isfinite(value) && value >= 0)) {
      throw std::invalid_argument(std::string(name) + " must be >= 0 (0 = relative to the scene)");
    }
  };
  check_distance(tau, "tau");
  check_distance(cutoff, "cutoff");
  if (!(std::isfinite(tau_relative) && tau_relative > 0)) {
    throw std::invalid_argument("tau_rel must be a positive fraction");
  }
  if (!(std::isfinite(cutoff_relative) && cutoff_relative > 0)) {
    throw std::invalid_argument("cutoff_rel must be a positive fraction");
  }
  if (gt_stride < 1) throw std::invalid_argument("gt_stride must be >= 1");
  if (!(std::isfinite(png_max_rel_error) && png_max_rel_error > 0)) {
    throw std::invalid_argument("png_max_rel_error must be positive");
  }
}

fs::path GroundTruthDepthDir(const colmap_io::Workspace& workspace) {
  return workspace.root() / "ground_truth" / "depth_maps";
}

fs::path GroundTruthCloudPath(const colmap_io::Workspace& workspace) {
  return workspace.root() / "ground_truth" / "points.ply";
}

std::vector<std::string> DiscoverDepthMapTypes(const colmap_io::Workspace& workspace,
                                               const colmap_io::SparseModel& model) {
  std::set<std::string> names;
  for (const auto& [id, image] : model.images) names.insert(image.name);
  const fs::path dir = workspace.DepthMapsDir();
  std::set<std::string> types;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return {};
  fs::recursive_directory_iterator it(dir, ec);
  if (ec) throw IoError(dir.string(), "cannot list: " + ec.message());
  for (; it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) throw IoError(dir.string(), "cannot list: " + ec.message());
    std::error_code file_ec;
    if (!it->is_regular_file(file_ec)) continue;
    const std::string relative = it->path().lexically_relative(dir).generic_string();
    const std::string suffix = ".bin";
    if (relative.size() <= suffix.size() ||
        relative.compare(relative.size() - suffix.size(), suffix.size(), suffix) != 0) {
      continue;
    }
    const std::string stem = relative.substr(0, relative.size() - suffix.size());
    // Longest image name first: the rightmost dot that leaves a known name.
    for (std::size_t dot = stem.rfind('.'); dot != std::string::npos && dot > 0;
         dot = stem.rfind('.', dot - 1)) {
      if (dot + 1 < stem.size() && names.count(stem.substr(0, dot)) > 0) {
        types.insert(stem.substr(dot + 1));
        break;
      }
    }
  }
  return {types.begin(), types.end()};
}

namespace {

// The images of the model in name order, split by whether they have a GT
// depth map; throws IoError when the GT folder is missing or holds none.
struct GroundTruthImages {
  fs::path dir;
  std::vector<const colmap_io::Image*> with_gt;
  std::vector<const colmap_io::Image*> without_gt;
};

GroundTruthImages FindGroundTruthImages(const colmap_io::Workspace& workspace,
                                        const colmap_io::SparseModel& model) {
  std::vector<const colmap_io::Image*> images;
  for (const auto& [id, image] : model.images) images.push_back(&image);
  std::sort(images.begin(), images.end(),
            [](const auto* a, const auto* b) { return a->name < b->name; });
  GroundTruthImages gt;
  gt.dir = GroundTruthDepthDir(workspace);
  std::error_code ec;
  if (!fs::is_directory(gt.dir, ec)) {
    throw IoError(gt.dir.string(),
                  "no ground truth: expected a depth map NAME.bin per image in this folder");
  }
  for (const colmap_io::Image* image : images) {
    workspace.ImagePath(image->name);  // refuses names that would leave the workspace
    (IsFile(gt.dir / (image->name + ".bin")) ? gt.with_gt : gt.without_gt).push_back(image);
  }
  if (gt.with_gt.empty()) {
    throw IoError(gt.dir.string(), "no ground-truth depth map NAME.bin for any of the " +
                                       std::to_string(images.size()) +
                                       " images of the sparse model");
  }
  return gt;
}

// The depth-map types to score (the options', else those found), each with
// its count of maps of images without GT; throws IoError when no image with
// GT has a map of any of them (checked before reading anything big).
std::vector<TypeDepthResult> ChooseTypes(const colmap_io::Workspace& workspace,
                                         const colmap_io::SparseModel& model,
                                         const GroundTruthImages& gt,
                                         const WorkspaceEvalOptions& options) {
  std::vector<std::string> types;
  for (const std::string& type :
       options.types.empty() ? DiscoverDepthMapTypes(workspace, model) : options.types) {
    if (std::find(types.begin(), types.end(), type) == types.end()) types.push_back(type);
  }
  if (types.empty()) {
    throw IoError(workspace.DepthMapsDir().string(),
                  "no depth maps NAME.TYPE.bin for the images of the sparse model");
  }
  std::vector<TypeDepthResult> results;
  bool any_map = false;
  for (const std::string& type : types) {
    TypeDepthResult result;
    result.type = type;
    for (const colmap_io::Image* image : gt.without_gt) {
      if (IsFile(workspace.DepthMapPath(image->name, type))) ++result.maps_without_gt;
    }
    for (const colmap_io::Image* image : gt.with_gt) {
      any_map = any_map || IsFile(workspace.DepthMapPath(image->name, type));
    }
    results.push_back(std::move(result));
  }
  if (!any_map) {
    std::string list;
    for (const std::string& type : types) list += (list.empty() ? "" : ", ") + type;
    throw IoError(workspace.DepthMapsDir().string(),
                  "no depth map of type(s) " + list + " for any image with ground truth");
  }
  return results;
}

// What the views of one type add up to.
struct TypeSums {
  DepthMetricSums depth;
  DisparityMetricSums disparity;
};

// Scores every map of one image with GT, adding to report->types and `sums`;
// back-projects the GT into `gt_cloud` when given; writes the PNGs when
// options.png_dir is set.
// The GT depth map of `image` (GT_DIR/NAME.bin), checked to be its camera's
// size or a clean down-scale of it.
colmap_io::DenseArray ReadGroundTruthMap(const colmap_io::SparseModel& model, const fs::path& gt_dir,
                                         const colmap_io::Image& image) {
  const fs::path gt_path = gt_dir / (image.name + ".bin");
  colmap_io::DenseArray gt = ReadDepthMap(gt_path, "ground-truth depth map");
  const colmap_io::Camera& camera = model.cameras.at(image.camera_id);
  if (camera.width > colmap_io::kMaxDenseArraySide ||
      camera.height > colmap_io::kMaxDenseArraySide ||
      !IsCleanScale(gt.width(), gt.height(), static_cast<int>(camera.width),
                    static_cast<int>(camera.height))) {
    throw IoError(gt_path.string(), "ground-truth depth map is " +
                                        SizeText(gt.width(), gt.height()) +
                                        " but its camera is " +
                                        SizeText(camera.width, camera.height));
  }
  return gt;
}

// Scores every type's map of `image` against `gt`, its GT depth map
// (ReadGroundTruthMap).
void EvaluateImage(const colmap_io::Workspace& workspace, const colmap_io::SparseModel& model,
                   const fs::path& gt_dir, const colmap_io::Image& image, const colmap_io::DenseArray& gt,
                   const WorkspaceEvalOptions& options, const RegionLabels* region_labels,
                   std::vector<TypeSums>* sums, PointCloud* gt_cloud, WorkspaceEvalReport* report) {
  const fs::path gt_path = gt_dir / (image.name + ".bin");
  const colmap_io::Camera& camera = model.cameras.at(image.camera_id);
  std::optional<DisparityGeometry> disparity_geometry;
  if (std::optional<RectifiedPartner> partner = FindRectifiedPartner(model, image.image_id)) {
    // Disparity in pixels of the GT's resolution, whatever the map's.
    const double focal =
        camera.CalibrationMatrix()(0, 0) * gt.width() / static_cast<double>(camera.width);
    disparity_geometry = DisparityGeometry{std::move(*partner), focal};
    ++report->views_with_rectified_partner;
  }
  if (gt_cloud != nullptr) {
    try {
      BackProjectDepthMap(gt, camera, image, options.gt_stride, gt_cloud);
    } catch (const std::invalid_argument& error) {
      throw IoError(gt_path.string(), error.what());
    }
  }
  const bool write_png = !options.png_dir.empty();
  DepthRange colour_range;
  if (write_png) {
    colour_range = ValidDepthRange(gt);
    WritePngAtomically(ColouriseDepth(gt, colour_range), PngPath(options.png_dir, image.name, "gt"));
    ++report->png_files;
  }
  for (std::size_t t = 0; t < report->types.size(); ++t) {
    const std::string& type = report->types[t].type;
    const fs::path map_path = workspace.DepthMapPath(image.name, type);
    if (!IsFile(map_path)) {
      // dispmvs_colmap's maps (dispmvs.*) are missing where its run failed:
      // its record says why.
      if (type.rfind("dispmvs.", 0) == 0) {
        const std::optional<colmap_io::ViewRecord> record =
            colmap_io::ReadViewRecord(colmap_io::ViewRecordPath(workspace, image.name));
        if (record && !record->failure.empty()) {
          report->types[t].failed_views.push_back({image.name, record->failure});
        }
      }
      continue;
    }
    const colmap_io::DenseArray map = ReadDepthMap(map_path, "depth map");
    // The confidence map, when there is one of the depth map's size: its
    // ranking reads the relative errors the depth metrics compute.
    std::optional<colmap_io::DenseArray> confidence;
    const fs::path confidence_path = workspace.ConfidenceMapPath(image.name, type);
    if (IsFile(confidence_path)) {
      confidence = ReadDepthMap(confidence_path, "confidence map");
      if (confidence->width() != map.width() || confidence->height() != map.height()) confidence.reset();
    }
    cv::Mat rel_error;
    DepthMetricSums view_sums;
    DisparityMetricSums disparity_sums;
    try {
      view_sums = SumDepthMetrics(map, gt, write_png || confidence || region_labels ? &rel_error : nullptr);
      if (disparity_geometry) {
        disparity_sums = SumDisparityMetrics(
            map, gt, disparity_geometry->focal * disparity_geometry->partner.baseline);
      }
    } catch (const std::invalid_argument& error) {
      throw IoError(map_path.string(), error.what());
    }
    if (write_png) {
      WritePngAtomically(ColouriseDepth(map, colour_range),
                         PngPath(options.png_dir, image.name, type + ".depth"));
      WritePngAtomically(ColouriseRelError(rel_error, options.png_max_rel_error),
                         PngPath(options.png_dir, image.name, type + ".error"));
      report->png_files += 2;
    }
    ViewDepthResult view;
    view.image_name = image.name;
    view.width = map.width();
    view.height = map.height();
    view.gt_width = gt.width();
    view.gt_height = gt.height();
    view.metrics = Finalize(view_sums);
    view.disparity_geometry = disparity_geometry;
    view.disparity = Finalize(disparity_sums);
    report->types[t].views.push_back(std::move(view));
    if (region_labels) report->types[t].regions += SumErrorRegions(rel_error, *region_labels);
    if (confidence) {
      report->types[t].confidence_ranking += SumConfidenceRanking(rel_error, *confidence);
      ++report->types[t].views_with_confidence;
    }
    (*sums)[t].depth += view_sums;
    (*sums)[t].disparity += disparity_sums;
  }
}

// Every GT map of `gt.with_gt`, in its order (for the region labels, which
// read all the other views' ground truth; the metrics then use these too).
std::vector<colmap_io::DenseArray> ReadAllGroundTruth(const colmap_io::SparseModel& model,
                                                     const GroundTruthImages& gt) {
  std::vector<colmap_io::DenseArray> maps;
  for (const colmap_io::Image* image : gt.with_gt) maps.push_back(ReadGroundTruthMap(model, gt.dir, *image));
  return maps;
}

// The region labels of view `index` of `gt.with_gt` against all the others.
RegionLabels LabelRegionsOfView(const colmap_io::SparseModel& model, const GroundTruthImages& gt,
                                const std::vector<colmap_io::DenseArray>& maps, std::size_t index) {
  std::vector<OtherView> others;
  for (std::size_t j = 0; j < gt.with_gt.size(); ++j) {
    if (j == index) continue;
    others.push_back({&maps[j], &model.cameras.at(gt.with_gt[j]->camera_id), gt.with_gt[j]});
  }
  const colmap_io::Image& image = *gt.with_gt[index];
  return LabelRegions(maps[index], model.cameras.at(image.camera_id), image, others);
}

// The GT cloud (from ground_truth/points.ply, else `cloud_from_maps`), its
// thresholds, and each reconstruction scored against it.
void EvaluateClouds(const colmap_io::Workspace& workspace, const fs::path& gt_dir,
                    bool gt_from_maps, PointCloud cloud_from_maps,
                    const WorkspaceEvalOptions& options, WorkspaceEvalReport* report) {
  const fs::path gt_cloud_path = GroundTruthCloudPath(workspace);
  PointCloud gt_cloud = std::move(cloud_from_maps);
  GtCloudInfo info;
  if (gt_from_maps) {
    info.source = "ground-truth depth maps (stride " + std::to_string(options.gt_stride) + ")";
  } else {
    info.source = gt_cloud_path.string();
    info.nonfinite_dropped = AppendFinitePoints(colmap_io::ReadPlyPoints(gt_cloud_path), &gt_cloud);
  }
  if (gt_cloud.empty()) {
    throw IoError(gt_from_maps ? gt_dir.string() : gt_cloud_path.string(),
                  "the ground-truth point cloud is empty");
  }
  info.num_points = static_cast<int64_t>(gt_cloud.size());
  info.bbox_diagonal = BoundingBoxDiagonal(gt_cloud);
  info.tau_relative = options.tau == 0;
  info.cutoff_relative = options.cutoff == 0;
  info.thresholds.tau = info.tau_relative ? options.tau_relative * info.bbox_diagonal : options.tau;
  info.thresholds.cutoff =
      info.cutoff_relative ? options.cutoff_relative * info.bbox_diagonal : options.cutoff;
  if (!(info.thresholds.tau > 0) || !(info.thresholds.cutoff > 0)) {
    throw IoError(info.source, "the ground-truth cloud has no extent (bounding-box diagonal " +
                                   std::to_string(info.bbox_diagonal) +
                                   "): give --tau and --cutoff in scene units");
  }
  const NearestNeighbourIndex gt_index(std::move(gt_cloud));
  for (const std::string& ply : options.ply_paths) {
    CloudResult result;
    result.ply_path = ply;
    PointCloud points;
    result.nonfinite_dropped = AppendFinitePoints(colmap_io::ReadPlyPoints(ply), &points);
    const NearestNeighbourIndex index(std::move(points));
    result.metrics = EvaluateCloud(index, gt_index, info.thresholds);
    report->clouds.push_back(std::move(result));
  }
  report->gt_cloud = info;
}

}  // namespace

WorkspaceEvalReport EvaluateWorkspace(const fs::path& workspace_path,
                                      const WorkspaceEvalOptions& options) {
  options.Check();
  const colmap_io::Workspace workspace(workspace_path);
  const colmap_io::SparseModel model = workspace.ReadModel();

  WorkspaceEvalReport report;
  report.workspace = workspace.root().string();
  report.num_images = static_cast<int>(model.images.size());
  const GroundTruthImages gt = FindGroundTruthImages(workspace, model);
  report.views_with_gt = static_cast<int>(gt.with_gt.size());
  report.types = ChooseTypes(workspace, model, gt, options);

  // Clouds: check the files exist before the long part.
  const bool evaluate_clouds = !options.ply_paths.empty();
  const bool gt_cloud_from_maps = evaluate_clouds && !IsFile(GroundTruthCloudPath(workspace));
  for (const std::string& ply : options.ply_paths) {
    if (!IsFile(ply)) throw IoError(ply, "no such file");
  }

  // Depth maps, view by view (each GT read once).
  std::vector<TypeSums> sums(report.types.size());
  PointCloud gt_cloud;
  const std::vector<colmap_io::DenseArray> gt_maps = options.regions ? ReadAllGroundTruth(model, gt) :
                                                                         std::vector<colmap_io::DenseArray>{};
  for (std::size_t i = 0; i < gt.with_gt.size(); ++i) {
    const colmap_io::Image* image = gt.with_gt[i];
    // Each GT map read once: with regions all are in memory already.
    std::optional<colmap_io::DenseArray> read_now;
    const colmap_io::DenseArray& gt_map =
        options.regions ? gt_maps[i] : read_now.emplace(ReadGroundTruthMap(model, gt.dir, *image));
    std::optional<RegionLabels> labels;
    if (options.regions) labels = LabelRegionsOfView(model, gt, gt_maps, i);
    EvaluateImage(workspace, model, gt.dir, *image, gt_map, options, labels ? &*labels : nullptr, &sums,
                  gt_cloud_from_maps ? &gt_cloud : nullptr, &report);
  }
  for (std::size_t t = 0; t < report.types.size(); ++t) {
    report.types[t].overall = Finalize(sums[t].depth);
    report.types[t].disparity_overall = Finalize(sums[t].disparity);
    report.types[t].sums = std::move(sums[t].depth);
    report.types[t].disparity_sums = sums[t].disparity;
  }

  if (evaluate_clouds) {
    EvaluateClouds(workspace, gt.dir, gt_cloud_from_maps, std::move(gt_cloud), options, &report);
  }
  return report;
}

}  // namespace dispmvs::eval
