#include "dense/geometric_pass.h"

#include <algorithm>
#include <cstddef>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "colmap_io/atomic_file.h"
#include "colmap_io/dense_array.h"
#include "dense/workspace_maps.h"

namespace dispmvs::dense {

namespace fs = std::filesystem;
using namespace colmap_io;

PassSummary RunGeometricPass(const Workspace& workspace, const DensePlan& plan,
                             const fusion::GeometricFilterOptions& options, std::ostream& log,
                             const ImageMasks& masks) {
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
      fusion::DepthView ref = LoadDepthView(workspace, plan, reference, kPhotometricType);
      const double photometric_share = ValidFraction(ref.depth);
      const std::size_t ignored = masks.Apply(name, &ref);
      // A source whose map cannot be read is left out, as fusion leaves it
      // out: it fails its own view, not every view that lists it.
      std::vector<fusion::DepthView> sources;
      for (image_t source : problem.source_image_ids) {
        const std::string& source_name = plan.ImageOf(source).name;
        if (!fs::is_regular_file(PathsOf(workspace, source_name, kPhotometricType).depth)) continue;
        try {
          sources.push_back(LoadDepthView(workspace, plan, source, kPhotometricType));
          masks.Apply(source_name, &sources.back());
        } catch (const std::exception& error) {
          log << "geometric: " << name << ": source " << source_name
              << " left out: " << error.what() << '\n';
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
          << Percent(photometric_share);
      if (ignored > 0) {
        log << ", the mask ignores " << Percent(static_cast<double>(ignored) / static_cast<double>(ref.depth.size()));
      }
      log << ")\n"
          << std::flush;  // progress a user (or a scheduler's log) can follow
    } catch (const std::exception& error) {
      summary.failures.push_back(name + ": " + error.what());
      log << "geometric: " << name << ": FAILED: " << error.what() << '\n' << std::flush;
    }
  }
  log << std::flush;
  summary.seconds = SecondsSince(start);
  return summary;
}

int RemoveGeometricLeftovers(const Workspace& workspace, const DensePlan& plan) {
  // Image names may hold folders, so the maps of one type can lie in several
  // folders: each is listed once, and in the common case none has any.
  std::map<fs::path, std::vector<std::string>> names_with_temporaries;
  int removed = 0;
  for (const auto& [image_id, image] : plan.model.images) {
    const MapPaths paths = PathsOf(workspace, image.name, kGeometricType);
    for (const fs::path& path : {paths.depth, paths.normal, paths.confidence}) {
      auto folder = names_with_temporaries.find(path.parent_path());
      if (folder == names_with_temporaries.end()) {
        folder = names_with_temporaries
                     .emplace(path.parent_path(), NamesWithTemporaries(path.parent_path()))
                     .first;
      }
      if (std::binary_search(folder->second.begin(), folder->second.end(),
                             path.filename().string())) {
        removed += RemoveLeftoverTemporaries(path);
      }
    }
  }
  return removed;
}

}  // namespace dispmvs::dense
