#include "src/dense_passes.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>
#include <system_error>

#include <opencv2/core.hpp>

#include "colmap_io/atomic_file.h"
#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/image_io.h"
#include "colmap_io/stereo_config.h"
#include "fusion/depth_normals.h"
#include "fusion/point_fusion.h"
#include "fusion/vis_file.h"

namespace dispmvs::dense {

namespace fs = std::filesystem;
using namespace colmap_io;

namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

std::string FormatDuration(double seconds) {
  const auto total = static_cast<long long>(std::max(0.0, seconds) + 0.5);
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%lld:%02lld:%02lld", total / 3600, total / 60 % 60,
                total % 60);
  return buffer;
}

std::string FormatSeconds(double seconds) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.2f s", seconds);
  return buffer;
}

// Seed of a view's random initialisation: fixed per (run seed, image), so
// results do not depend on order, sharding or resumption.
uint64_t ViewSeed(uint64_t seed, image_t image_id) {
  uint64_t x = seed + 0x9E3779B97F4A7C15ull * (static_cast<uint64_t>(image_id) + 1);
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

struct MapPaths {
  fs::path depth, normal, confidence;
  bool AllExist() const {
    return fs::is_regular_file(depth) && fs::is_regular_file(normal) &&
           fs::is_regular_file(confidence);
  }
};

MapPaths PathsOf(const Workspace& workspace, const std::string& name, const std::string& type) {
  return {workspace.DepthMapPath(name, type), workspace.NormalMapPath(name, type),
          workspace.ConfidenceMapPath(name, type)};
}

// The depth map is written last: its presence marks a complete view.
void WriteMaps(const MapPaths& paths, const DenseArray& depth, const DenseArray& normal,
               const DenseArray& confidence) {
  WriteDenseArray(confidence, paths.confidence);
  WriteDenseArray(normal, paths.normal);
  WriteDenseArray(depth, paths.depth);
}

// The full-size image of `image_id`, checked against its camera.
ResizedImage ReadFullImage(const Workspace& workspace, const DensePlan& plan, image_t image_id) {
  const Image& image = plan.ImageOf(image_id);
  return ReadImageForCamera(workspace.ImagePath(image.name), plan.model.cameras.at(image.camera_id),
                            /*max_image_size=*/-1);
}

ProblemView MakeView(const ResizedImage& full, const Image& image, const cv::Size& size) {
  const ResizedImage grid = ResampleToDenseIndexGrid(full.image, full.K, size);
  ProblemView view;
  view.image = grid.image;
  view.K = grid.K;
  view.R = image.RotationMatrix();
  view.t = image.tvec;
  return view;
}

// The reference at the --max_image_size size, its sources brought to the
// same size (per-axis scaled intrinsics keep them exact).
std::vector<ProblemView> LoadProblemViews(const Workspace& workspace, const DensePlan& plan,
                                          const StereoProblem& problem, int max_image_size) {
  const ResizedImage reference = ReadFullImage(workspace, plan, problem.reference_image_id);
  const cv::Size size = ComputeResizedSize(reference.image.size(), max_image_size);
  std::vector<ProblemView> views;
  views.push_back(MakeView(reference, plan.ImageOf(problem.reference_image_id), size));
  for (image_t source : problem.source_image_ids) {
    views.push_back(MakeView(ReadFullImage(workspace, plan, source), plan.ImageOf(source), size));
  }
  return views;
}

// Camera geometry of an image's map of size `map_size`.
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

// Depth and confidence maps of `type` as a DepthView; throws IoError on
// unreadable or inconsistent files.
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

std::string Percent(double fraction) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f%%", 100.0 * fraction);
  return buffer;
}

}  // namespace

void PhotometricOptions::Check() const {
  estimator.Check();
  if (max_image_size == 0 || max_image_size < -1) {
    throw std::invalid_argument("--max_image_size must be positive, or -1 for full size");
  }
}

PassSummary RunPhotometricPass(const Workspace& workspace, const DensePlan& plan,
                               const PhotometricOptions& options, std::ostream& log) {
  options.Check();
  const auto start = Clock::now();
  PassSummary summary;
  workspace.CreateStereoFolders();

  // Work out what is left before loading the network (a finished run
  // resumes instantly).
  std::vector<const StereoProblem*> todo;
  for (const StereoProblem& problem : plan.problems) {
    const std::string& name = plan.ImageOf(problem.reference_image_id).name;
    if (problem.source_image_ids.empty()) {
      ++summary.skipped_no_sources;
      log << "photometric: " << name << ": no usable source view, skipped\n";
    } else if (!options.overwrite && PathsOf(workspace, name, kPhotometricType).AllExist()) {
      ++summary.skipped_existing;
    } else {
      todo.push_back(&problem);
    }
  }
  log << "photometric: " << todo.size() << " view(s) to compute, " << summary.skipped_existing
      << " already done" << (summary.skipped_existing > 0 ? " (kept; --overwrite recomputes)" : "")
      << '\n';
  if (todo.empty()) {
    summary.seconds = SecondsSince(start);
    return summary;
  }

  // A missing hint fails the whole pass here, not once per view.
  std::vector<image_t> without_hint;
  for (const StereoProblem* problem : todo) {
    if (!plan.HintFor(problem->reference_image_id)) {
      without_hint.push_back(problem->reference_image_id);
    }
  }
  CheckHintsForWeights(
      plan, without_hint,
      DepthEstimator::CheckWeightsFile(options.estimator.model_path).needs_depth_range);
  DepthEstimator estimator(options.estimator);
  log << "photometric: network " << estimator.Describe() << '\n' << std::flush;
  const auto compute_start = Clock::now();
  for (std::size_t i = 0; i < todo.size(); ++i) {
    const StereoProblem& problem = *todo[i];
    const image_t reference = problem.reference_image_id;
    const std::string& name = plan.ImageOf(reference).name;
    const auto view_start = Clock::now();
    log << "photometric: [" << i + 1 << "/" << todo.size() << "] " << name << " ("
        << problem.source_image_ids.size() << " sources)";
    try {
      // None without sparse points or --depth_min/--depth_max: fine for
      // model v2 weights (checked above for the others).
      const std::optional<DepthRange> hint = plan.HintFor(reference);
      const std::vector<ProblemView> views =
          LoadProblemViews(workspace, plan, problem, options.max_image_size);
      const DepthEstimate estimate =
          estimator.Estimate(views, hint, ViewSeed(options.seed, reference));
      const DenseArray normal = fusion::NormalMapFromDepth(estimate.depth, views[0].K);
      WriteMaps(PathsOf(workspace, name, kPhotometricType), estimate.depth, normal,
                estimate.confidence);
      ++summary.done;
      const double per_view = SecondsSince(compute_start) / static_cast<double>(i + 1);
      log << ": " << FormatSeconds(SecondsSince(view_start)) << ", "
          << views[0].image.cols << "x" << views[0].image.rows << ", depth at "
          << Percent(ValidFraction(estimate.depth)) << " of pixels, ETA "
          << FormatDuration(per_view * static_cast<double>(todo.size() - i - 1)) << '\n'
          << std::flush;
    } catch (const std::exception& error) {
      summary.failures.push_back(name + ": " + error.what());
      log << ": FAILED: " << error.what() << '\n' << std::flush;
    }
  }
  summary.seconds = SecondsSince(start);
  return summary;
}

PassSummary RunGeometricPass(const Workspace& workspace, const DensePlan& plan,
                             const fusion::GeometricFilterOptions& options, std::ostream& log) {
  options.Check();
  const auto start = Clock::now();
  PassSummary summary;
  workspace.CreateStereoFolders();
  for (const StereoProblem& problem : plan.problems) {
    const image_t reference = problem.reference_image_id;
    const std::string& name = plan.ImageOf(reference).name;
    const MapPaths input = PathsOf(workspace, name, kPhotometricType);
    if (!fs::is_regular_file(input.depth)) {
      ++summary.skipped_no_sources;  // nothing to filter (failed or skipped view)
      continue;
    }
    try {
      const fusion::DepthView ref = LoadDepthView(workspace, plan, reference, kPhotometricType);
      std::vector<fusion::DepthView> sources;
      for (image_t source : problem.source_image_ids) {
        if (fs::is_regular_file(PathsOf(workspace, plan.ImageOf(source).name, kPhotometricType).depth)) {
          sources.push_back(LoadDepthView(workspace, plan, source, kPhotometricType));
        }
      }
      std::vector<const fusion::DepthView*> source_pointers;
      for (const auto& source : sources) source_pointers.push_back(&source);
      fusion::GeometricFilterOptions reference_options = options;
      const auto lowered = plan.min_consistent_views.find(reference);
      if (lowered != plan.min_consistent_views.end()) {
        reference_options.min_consistent_views = lowered->second;
      }
      const fusion::GeometricFilterResult result =
          fusion::FilterDepthMap(ref, source_pointers, reference_options);
      DenseArray normal = ReadNormalsMatching(input.normal, ref.depth);
      DenseArray confidence =
          ref.confidence.empty() ? DenseArray(ref.depth.width(), ref.depth.height(), 1, 1.0f)
                                 : ref.confidence;
      const std::size_t plane = result.depth.size();
      for (std::size_t i = 0; i < plane; ++i) {
        if (result.depth.data()[i] > 0) continue;
        confidence.data()[i] = 0;
        for (int c = 0; c < 3; ++c) normal.data()[c * plane + i] = 0;
      }
      WriteMaps(PathsOf(workspace, name, kGeometricType), result.depth, normal, confidence);
      ++summary.done;
      log << "geometric: " << name << ": " << sources.size() << " source map(s), kept "
          << Percent(ValidFraction(result.depth)) << " of pixels (photometric "
          << Percent(ValidFraction(ref.depth)) << ")\n";
    } catch (const std::exception& error) {
      summary.failures.push_back(name + ": " + error.what());
      log << "geometric: " << name << ": FAILED: " << error.what() << '\n';
    }
  }
  log << std::flush;
  summary.seconds = SecondsSince(start);
  return summary;
}

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

namespace {

// Copies `from` to `to` through a temporary name.
void CopyAtomically(const fs::path& from, const fs::path& to) {
  std::ifstream in(from, std::ios::binary);
  if (!in) throw IoError(from.string(), "cannot open for reading");
  WriteFileAtomically(to, [&](std::ostream& out) {
    out << in.rdbuf();
    if (in.bad()) throw IoError(from.string(), "read failed");
  });
}

// A symbolic link at `link` to `target`, unless `link` already is one to it.
void EnsureSymlink(const fs::path& target, const fs::path& link) {
  std::error_code error;
  if (fs::is_symlink(link)) {
    if (fs::equivalent(link, target, error)) return;
    throw IoError(link.string(), "exists and links elsewhere");
  }
  if (fs::exists(link)) throw IoError(link.string(), "exists and is not a link to the workspace");
  fs::create_directory_symlink(target, link, error);
  if (error) throw IoError(link.string(), "cannot create link: " + error.message());
}

}  // namespace

int ExportForColmap(const Workspace& workspace, const DensePlan& plan, const fs::path& export_root,
                    std::ostream& log) {
  const fs::path root = fs::absolute(export_root);
  if (fs::equivalent(root, workspace.root()) ||
      (fs::exists(root) && fs::equivalent(root, fs::absolute(workspace.root())))) {
    throw std::invalid_argument("--export_path must differ from the workspace");
  }
  std::error_code error;
  fs::create_directories(root, error);
  if (error) throw IoError(root.string(), "cannot create folder: " + error.message());
  EnsureSymlink(fs::canonical(workspace.ImagesDir()), root / "images");
  EnsureSymlink(fs::canonical(workspace.SparseDir()), root / "sparse");
  const Workspace exported(root);
  exported.CreateStereoFolders();

  std::vector<PatchMatchEntry> entries;
  std::vector<std::string> fusion_list;
  int exported_images = 0;
  for (const StereoProblem& problem : plan.problems) {
    const std::string& name = plan.ImageOf(problem.reference_image_id).name;
    bool any = false;
    for (const auto& [ours, theirs] : {std::pair<const char*, const char*>{kPhotometricType, "photometric"},
                                       {kGeometricType, "geometric"}}) {
      const MapPaths from = PathsOf(workspace, name, ours);
      if (!fs::is_regular_file(from.depth) || !fs::is_regular_file(from.normal)) continue;
      CopyAtomically(from.normal, exported.NormalMapPath(name, theirs));
      CopyAtomically(from.depth, exported.DepthMapPath(name, theirs));
      any = true;
    }
    if (!any) continue;
    ++exported_images;
    fusion_list.push_back(name);
    std::vector<std::string> sources;
    for (image_t source : problem.source_image_ids) sources.push_back(plan.ImageOf(source).name);
    if (sources.empty()) continue;
    PatchMatchEntry entry;
    entry.reference = name;
    entry.sources = SourceSpec::Explicit(std::move(sources));
    entries.push_back(std::move(entry));
  }
  WritePatchMatchConfig(entries, exported.PatchMatchConfigPath());
  WriteFusionConfig(fusion_list, exported.FusionConfigPath());
  log << "export: " << exported_images << " image(s) under COLMAP's names in " << root.string()
      << "\n  fuse with: colmap stereo_fusion --workspace_path " << root.string()
      << " --input_type geometric --output_path " << (root / "fused.ply").string() << '\n';
  return exported_images;
}

}  // namespace dispmvs::dense
