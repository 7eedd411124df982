#include "eval/method_comparison.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/image_io.h"
#include "colmap_io/ply.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/workspace.h"
#include "eval/depth_metrics.h"

namespace dispmvs::eval {

namespace fs = std::filesystem;
using namespace colmap_io;

fusion::GeometricFilterOptions MethodComparisonOptions::DefaultConsistency() {
  fusion::GeometricFilterOptions options;
  options.min_consistent_views = 1;
  return options;
}

void MethodComparisonOptions::Check() const {
  if (type_a.empty() || type_b.empty()) throw std::invalid_argument("--compare needs two types");
  if (type_a == type_b) throw std::invalid_argument("--compare needs two different types");
  if (ply_a.empty() != ply_b.empty()) {
    throw std::invalid_argument("--compare_ply needs two point clouds, A,B");
  }
  if (!(tau_relative > 0) || !(cutoff_relative > 0) || !std::isfinite(tau_relative) ||
      !std::isfinite(cutoff_relative)) {
    throw std::invalid_argument("the relative tau and cut-off must be finite and > 0");
  }
  if (max_num_src_images < 1 ||
      static_cast<std::size_t>(max_num_src_images) > colmap_io::kMaxAutoSources) {
    throw std::invalid_argument("--max_num_src_images must be in [1, " +
                                std::to_string(colmap_io::kMaxAutoSources) + "], got " +
                                std::to_string(max_num_src_images));
  }
  consistency.Check();
}

AgreementSums& AgreementSums::operator+=(const AgreementSums& o) {
  pixels += o.pixels;
  valid_a += o.valid_a;
  valid_b += o.valid_b;
  shared += o.shared;
  within_1 += o.within_1;
  within_2 += o.within_2;
  within_5 += o.within_5;
  checked_a += o.checked_a;
  consistent_a += o.consistent_a;
  checked_b += o.checked_b;
  consistent_b += o.consistent_b;
  return *this;
}

namespace {

double Ratio(int64_t count, int64_t total) {
  return total > 0 ? static_cast<double>(count) / static_cast<double>(total)
                   : std::numeric_limits<double>::quiet_NaN();
}

bool Valid(float depth) { return std::isfinite(depth) && depth > 0; }

std::optional<DenseArray> ReadMapIfAny(const Workspace& workspace, const std::string& name,
                                       const std::string& type) {
  const fs::path path = workspace.DepthMapPath(name, type);
  std::optional<DenseArray> depth = colmap_io::ReadDenseArrayIfPresent(path);
  if (depth && depth->channels() != 1) throw IoError(path.string(), "depth map must have 1 channel");
  return depth;
}

// The camera geometry of `image`'s map of the size of `depth`.
fusion::DepthView ViewOf(const SparseModel& model, const Image& image, DenseArray depth) {
  const Camera& camera = model.cameras.at(image.camera_id);
  fusion::DepthView view;
  view.K = ScaleIntrinsics(camera.CalibrationMatrix(),
                           cv::Size(static_cast<int>(camera.width), static_cast<int>(camera.height)),
                           cv::Size(depth.width(), depth.height()));
  view.R = image.RotationMatrix();
  view.t = image.tvec;
  view.depth = std::move(depth);
  return view;
}

// Valid pixels of `reference` and how many of them enough of its sources'
// maps of `type` agree with (checked = 0 when no source has a map).
void CountConsistency(const Workspace& workspace, const SparseModel& model,
                      const fusion::DepthView& reference, const std::vector<image_t>& sources,
                      const std::string& type, const fusion::GeometricFilterOptions& options,
                      int64_t* checked, int64_t* consistent, int* used_sources) {
  std::vector<fusion::DepthView> views;
  for (image_t source : sources) {
    const Image& image = model.images.at(source);
    std::optional<DenseArray> depth = ReadMapIfAny(workspace, image.name, type);
    if (depth) views.push_back(ViewOf(model, image, std::move(*depth)));
  }
  *used_sources = static_cast<int>(views.size());
  if (views.empty()) return;
  std::vector<const fusion::DepthView*> pointers;
  for (const auto& view : views) pointers.push_back(&view);
  fusion::GeometricFilterOptions reference_options = options;
  reference_options.min_consistent_views =
      std::min(options.min_consistent_views, static_cast<int>(views.size()));
  const fusion::GeometricFilterResult result =
      fusion::FilterDepthMap(reference, pointers, reference_options);
  for (float d : reference.depth.values()) *checked += Valid(d) ? 1 : 0;
  *consistent += static_cast<int64_t>(result.num_kept);
}

// Per-pixel agreement of two maps, at the smaller map's size.
void CountAgreement(const DenseArray& a, const DenseArray& b, const std::string& name,
                    ViewComparison* view) {
  const bool a_smaller = a.size() <= b.size();
  const DenseArray& small = a_smaller ? a : b;
  const DenseArray& large = a_smaller ? b : a;
  if (!IsCleanScale(small.width(), small.height(), large.width(), large.height())) {
    throw std::invalid_argument(name + ": the maps are " + std::to_string(a.width()) + "x" +
                                std::to_string(a.height()) + " and " + std::to_string(b.width()) +
                                "x" + std::to_string(b.height()) +
                                ": not one size nor a down-scale of the other");
  }
  view->width = small.width();
  view->height = small.height();
  AgreementSums& sums = view->sums;
  for (int row = 0; row < small.height(); ++row) {
    const int large_row = NearestGtIndex(row, small.height(), large.height());
    for (int col = 0; col < small.width(); ++col) {
      const float s = small.at(row, col);
      const float l = large.at(large_row, NearestGtIndex(col, small.width(), large.width()));
      const float da = a_smaller ? s : l, db = a_smaller ? l : s;
      ++sums.pixels;
      sums.valid_a += Valid(da) ? 1 : 0;
      sums.valid_b += Valid(db) ? 1 : 0;
      if (!Valid(da) || !Valid(db)) continue;
      ++sums.shared;
      const double relative = 2.0 * std::abs(double{da} - db) / (double{da} + db);
      sums.within_1 += relative < 0.01 ? 1 : 0;
      sums.within_2 += relative < 0.02 ? 1 : 0;
      sums.within_5 += relative < 0.05 ? 1 : 0;
    }
  }
}

std::map<image_t, std::vector<image_t>> SourcesOf(const Workspace& workspace,
                                                  const SparseModel& model,
                                                  std::size_t max_num_sources) {
  const fs::path config = workspace.PatchMatchConfigPath();
  std::vector<PatchMatchEntry> entries = fs::is_regular_file(config)
                                             ? ReadPatchMatchConfig(config)
                                             : AutoPatchMatchConfig(model, max_num_sources);
  CapAutoSources(max_num_sources, &entries);
  // The sources dispmvs_colmap chooses with its defaults, the fallback to the
  // camera poses included (a workspace without sparse points).
  const std::map<image_t, DepthRange> ranges = ComputeDepthRanges(model);
  PoseSampleDepths sample_depths(model, ranges);
  std::map<image_t, std::vector<image_t>> sources;
  for (const StereoProblem& problem : ResolvePatchMatchConfigWithPoseFallback(
           entries, model, ViewSelectionOptions(), config.string(),
           [&](image_t reference) { return sample_depths.For(reference); })) {
    sources[problem.reference_image_id] = problem.source_image_ids;
  }
  return sources;
}

CloudComparison CompareClouds(const MethodComparisonOptions& options) {
  CloudComparison result;
  result.ply_a = options.ply_a;
  result.ply_b = options.ply_b;
  PointCloud a, b;
  result.nonfinite_dropped_a = AppendFinitePoints(ReadPlyPoints(options.ply_a), &a);
  result.nonfinite_dropped_b = AppendFinitePoints(ReadPlyPoints(options.ply_b), &b);
  if (b.empty()) throw IoError(options.ply_b, "the point cloud has no (finite) point");
  const double diagonal = BoundingBoxDiagonal(b);
  CloudMetricOptions metric_options;
  metric_options.tau = options.tau_relative * diagonal;
  metric_options.cutoff = options.cutoff_relative * diagonal;
  if (!(diagonal > 0)) {
    throw IoError(options.ply_b, "the point cloud has no extent (all points equal)");
  }
  const NearestNeighbourIndex index_a(std::move(a)), index_b(std::move(b));
  result.a_against_b = EvaluateCloud(index_a, index_b, metric_options);
  return result;
}

}  // namespace

Agreement Fractions(const AgreementSums& s) {
  Agreement f;
  f.coverage_a = Ratio(s.valid_a, s.pixels);
  f.coverage_b = Ratio(s.valid_b, s.pixels);
  f.shared = Ratio(s.shared, s.pixels);
  f.within_1 = Ratio(s.within_1, s.shared);
  f.within_2 = Ratio(s.within_2, s.shared);
  f.within_5 = Ratio(s.within_5, s.shared);
  f.consistency_a = Ratio(s.consistent_a, s.checked_a);
  f.consistency_b = Ratio(s.consistent_b, s.checked_b);
  return f;
}

MethodComparison CompareMethods(const fs::path& workspace_path,
                                const MethodComparisonOptions& options) {
  options.Check();
  const Workspace workspace(workspace_path);
  const SparseModel model = workspace.ReadModel();
  const std::map<image_t, std::vector<image_t>> sources =
      SourcesOf(workspace, model, static_cast<std::size_t>(options.max_num_src_images));
  MethodComparison report;
  report.workspace = workspace_path.string();
  report.type_a = options.type_a;
  report.type_b = options.type_b;
  std::vector<const Image*> images;
  for (const auto& [id, image] : model.images) images.push_back(&image);
  std::sort(images.begin(), images.end(),
            [](const Image* x, const Image* y) { return x->name < y->name; });
  bool any_map = false;
  for (const Image* image : images) {
    ViewComparison view;
    view.name = image->name;
    std::optional<DenseArray> a = ReadMapIfAny(workspace, image->name, options.type_a);
    std::optional<DenseArray> b = ReadMapIfAny(workspace, image->name, options.type_b);
    view.has_a = a.has_value();
    view.has_b = b.has_value();
    any_map = any_map || view.has_a || view.has_b;
    if (view.has_a && view.has_b) {
      CountAgreement(*a, *b, image->name, &view);
      const auto listed = sources.find(image->image_id);
      const std::vector<image_t> none;
      const std::vector<image_t>& own = listed == sources.end() ? none : listed->second;
      CountConsistency(workspace, model, ViewOf(model, *image, std::move(*a)), own, options.type_a,
                       options.consistency, &view.sums.checked_a, &view.sums.consistent_a,
                       &view.sources_a);
      CountConsistency(workspace, model, ViewOf(model, *image, std::move(*b)), own, options.type_b,
                       options.consistency, &view.sums.checked_b, &view.sums.consistent_b,
                       &view.sources_b);
      ++report.views_compared;
      report.pooled += view.sums;
    }
    report.views.push_back(std::move(view));
  }
  if (!any_map) {
    throw std::invalid_argument("no depth map of type " + options.type_a + " or " +
                                options.type_b + " in " + workspace.DepthMapsDir().string());
  }
  if (!options.ply_a.empty()) report.clouds = CompareClouds(options);
  return report;
}

}  // namespace dispmvs::eval
