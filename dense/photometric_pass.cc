#include "dense/photometric_pass.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "colmap_io/atomic_file.h"
#include "colmap_io/dense_array.h"
#include "colmap_io/view_record.h"
#include "dense/view_claim.h"
#include "dense/workspace_maps.h"
#include "fusion/depth_normals.h"
#include "synth/rng.h"

namespace dispmvs::dense {

using namespace colmap_io;

namespace {

// Views of this many pixels and more say which step they are in (each takes
// a minute or more at 4 megapixels on two cores).
constexpr std::size_t kStepsFromPixels = 4'000'000;

}  // namespace

// The image-th number of the SplitMix64 stream that starts at the run's seed.
uint64_t ViewSeed(uint64_t seed, image_t image_id) {
  return synth::SplitMix64(seed + 0x9E3779B97F4A7C15ull * static_cast<uint64_t>(image_id));
}

void PhotometricOptions::Check() const {
  estimator.Check();
  if (max_image_size == 0 || max_image_size < -1) {
    throw std::invalid_argument("--max_image_size must be positive, or -1 for full size");
  }
}

int RemoveRecordLeftovers(const Workspace& workspace, const std::vector<std::string>& complete) {
  // One listing of the records folder; in the common case it has nothing.
  const std::vector<std::string> with_leftovers =
      NamesWithTemporaries(ViewRecordFolder(workspace));
  if (with_leftovers.empty()) return 0;
  int removed = 0;
  for (const std::string& name : complete) {
    const std::filesystem::path record_path = ViewRecordPath(workspace, name);
    if (!std::binary_search(with_leftovers.begin(), with_leftovers.end(),
                            record_path.filename().string())) {
      continue;
    }
    // A process still writing this record holds the view's claim.
    const std::optional<ViewClaim> claim = ViewClaim::TryClaim(ClaimPath(workspace, name));
    if (claim) removed += RemoveLeftoverTemporaries(record_path);
  }
  return removed;
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
  std::vector<std::string> complete;
  for (const StereoProblem& problem : plan.problems) {
    const std::string& name = plan.ImageOf(problem.reference_image_id).name;
    if (problem.source_image_ids.empty()) {
      ++summary.skipped_no_sources;
      log << "photometric: " << name << ": no usable source view, skipped\n";
    } else if (!options.overwrite && PathsOf(workspace, name, kPhotometricType).AllExist()) {
      ++summary.skipped_existing;
      complete.push_back(name);
    } else {
      todo.push_back(&problem);
    }
  }
  const int record_leftovers = RemoveRecordLeftovers(workspace, complete);
  if (record_leftovers > 0) {
    log << "photometric: " << record_leftovers
        << " temporary record file(s) of an interrupted run removed\n";
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
  log << "photometric: network " << estimator.Describe() << ", weights "
      << options.estimator.model_path << '\n'
      << std::flush;
  const auto compute_start = Clock::now();
  std::set<std::string> unreadable_sources;  // whose reason the log has given
  for (std::size_t i = 0; i < todo.size(); ++i) {
    const StereoProblem& problem = *todo[i];
    const image_t reference = problem.reference_image_id;
    const std::string& name = plan.ImageOf(reference).name;
    const auto view_start = Clock::now();
    log << "photometric: [" << i + 1 << "/" << todo.size() << "] " << name << " ("
        << problem.source_image_ids.size() << " sources)";
    try {
      // Another process may hold the view (shards run at once, or the same
      // shard twice), or may have finished it since the list above was made.
      long holder = 0;
      const std::optional<ViewClaim> claim = ViewClaim::TryClaim(ClaimPath(workspace, name), &holder);
      if (!claim) {
        ++summary.skipped_claimed;
        log << ": skipped, another process";
        if (holder > 0) log << " (pid " << holder << ")";
        log << " is computing it\n" << std::flush;
        continue;
      }
      if (!options.overwrite && PathsOf(workspace, name, kPhotometricType).AllExist()) {
        ++summary.skipped_existing;
        log << ": written by another process meanwhile, kept\n" << std::flush;
        continue;
      }
      // Holding the claim, no other process writes this view's files: any
      // temporaries beside them are a killed run's, and go.
      const MapPaths paths = PathsOf(workspace, name, kPhotometricType);
      const std::filesystem::path record_path = ViewRecordPath(workspace, name);
      int leftovers = 0;
      for (const std::filesystem::path& path :
           {paths.depth, paths.normal, paths.confidence, record_path}) {
        leftovers += RemoveLeftoverTemporaries(path);
      }
      // None without sparse points or --depth_min/--depth_max: fine for
      // model v2 weights (checked above for the others).
      const std::optional<DepthRange> hint = plan.HintFor(reference);
      ProblemViews loaded;
      std::size_t num_views = 0;
      DepthEstimate estimate;
      try {
        loaded = LoadProblemViews(workspace, plan, problem, options.max_image_size);
        num_views = loaded.views.size();
        const Eigen::Matrix3d K_reference = loaded.views[0].K;
        // A large view takes a minute or more: its line says which step it
        // is in, and how long each took ("..., reading images 3.6 s,
        // encoders 4.3 s, network 14.6 s, refinement 10.4 s, writing 0.2 s:
        // 33.0 s, ..."). Smaller views keep one short line.
        const bool say_steps = loaded.views[0].image.total() >= kStepsFromPixels;
        std::optional<Clock::time_point> step_start;
        if (say_steps) {
          log << ", reading images";  // the first step, already done
          step_start = view_start;
        }
        const auto step = [&](const std::string& name) {
          if (!say_steps) return;
          if (step_start) log << ' ' << FormatSeconds(SecondsSince(*step_start));
          log << ", " << name << std::flush;
          step_start = Clock::now();
        };
        // The pixels move into the estimate, which frees each image once it
        // is in the network's input.
        estimate = estimator.Estimate(std::move(loaded.views), hint, ViewSeed(options.seed, reference), step);
        step("writing");
        WriteMaps(paths, estimate.depth, fusion::NormalMapFromDepth(estimate.depth, K_reference),
                  estimate.confidence);
        if (step_start) log << ' ' << FormatSeconds(SecondsSince(*step_start));
      } catch (const std::exception& error) {
        // Still holding the claim: say why, for the report and dispmvs_eval.
        // Best effort (the disk may be what failed); the error goes on.
        ViewRecord failed;
        failed.failure = error.what();
        try {
          WriteViewRecord(record_path, failed);
        } catch (const std::exception&) {
        }
        throw;
      }
      // For the run report; after the maps, so a complete view never waits
      // on it (a view killed in between just has no time in the report).
      ViewRecord record;
      record.seconds = SecondsSince(view_start);
      record.width = estimate.depth.width();
      record.height = estimate.depth.height();
      record.num_sources = static_cast<int>(num_views) - 1;
      record.device = options.estimator.device;
      std::string record_note;
      try {  // only the report needs it: not a reason to fail the view
        WriteViewRecord(record_path, record);
      } catch (const std::exception& error) {
        record_note = std::string(" (time not recorded: ") + error.what() + ")";
      }
      ++summary.done;
      const double per_view = SecondsSince(compute_start) / static_cast<double>(i + 1);
      log << ": " << FormatSeconds(record.seconds) << ", "
          << estimate.depth.width() << "x" << estimate.depth.height() << ", depth at "
          << Percent(ValidFraction(estimate.depth)) << " of pixels, ETA "
          << FormatDuration(per_view * static_cast<double>(todo.size() - i - 1)) << record_note;
      if (leftovers > 0) {
        log << " (" << leftovers << " temporary file(s) of an interrupted run removed)";
      }
      for (const ProblemViews::LeftOut& source : loaded.left_out) {
        // The reason once per run; the views after only name the source.
        log << "; source " << source.name << " left out: "
            << (unreadable_sources.insert(source.name).second ? source.reason
                                                               : "unreadable, see above");
      }
      log << '\n' << std::flush;
    } catch (const std::exception& error) {
      summary.failures.push_back(name + ": " + error.what());
      log << ": FAILED: " << error.what() << '\n' << std::flush;
    }
  }
  const DepthEstimator::EncoderUse encoders = estimator.encoder_use();
  log << "photometric: encoder ran on " << encoders.encoded << " image(s), reused "
      << encoders.reused << " time(s) (at most " << static_cast<int>(std::ceil(encoders.peak_cache_mb))
      << " MiB kept, --feature_cache_mb " << options.estimator.feature_cache_mb << ")\n";
  summary.seconds = SecondsSince(start);
  return summary;
}

}  // namespace dispmvs::dense
