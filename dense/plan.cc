#include "dense/plan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>
#include <stdexcept>

#include "colmap_io/error.h"

namespace dispmvs::dense {

using namespace colmap_io;

namespace {

void RequireFinite(double value, const char* option) {
  if (!std::isfinite(value)) {
    throw std::invalid_argument(std::string("--") + option + " must be a finite number");
  }
}

// Dense MVS needs undistorted images: pinhole cameras only, with focal
// lengths that can be inverted.
void CheckPinholeCameras(const SparseModel& model, const Workspace& workspace) {
  for (const auto& [image_id, image] : model.images) {
    const auto camera = model.cameras.find(image.camera_id);
    if (camera == model.cameras.end() || !camera->second.IsPinhole()) {
      throw IoError(workspace.SparseDir().string(),
                    "image \"" + image.name +
                        "\" does not use a PINHOLE or SIMPLE_PINHOLE camera; dense "
                        "reconstruction needs the output of `colmap image_undistorter`");
    }
    // A zero or negative focal length passes the readers (COLMAP can store
    // one) but has no inverse: say so now, not once per view later.
    const Eigen::Matrix3d K = camera->second.CalibrationMatrix();
    if (!(K(0, 0) > 0 && K(1, 1) > 0)) {
      throw IoError(workspace.SparseDir().string(),
                    "camera " + std::to_string(camera->first) + " of image \"" + image.name +
                        "\" has a focal length that is not positive (fx " +
                        std::to_string(K(0, 0)) + ", fy " + std::to_string(K(1, 1)) + ")");
    }
  }
}

// The stereo problems: from patch-match.cfg, or `__auto__` for every image.
// Applies --max_num_src_images to `__auto__` entries. An `__auto__` reference
// sharing no sparse point with another image would get no source from
// COLMAP's rule; it gets them from the camera poses instead (needs the
// depth ranges: call after they are set).
void PlanProblems(const Workspace& workspace, const PlanOptions& options, DensePlan* plan) {
  const std::filesystem::path config_path = workspace.PatchMatchConfigPath();
  std::vector<PatchMatchEntry> entries;
  const auto max_sources = static_cast<std::size_t>(options.max_num_src_images);
  if (std::filesystem::exists(config_path)) {
    entries = ReadPatchMatchConfig(config_path);
    plan->problems_source = config_path.string();
    if (entries.empty()) {  // else the run would do nothing and say little
      throw IoError(config_path.string(),
                    "names no reference image (an empty file?): list the references and their "
                    "sources, or delete it to reconstruct every image with `__auto__` sources");
    }
  } else {
    entries = AutoPatchMatchConfig(plan->model, max_sources);
    plan->problems_source =
        "no patch-match.cfg: __auto__, " + std::to_string(max_sources) + " for every image";
  }
  CapAutoSources(max_sources, &entries);
  // The pose-based selection samples the image's hint before widening (the
  // widening tests the network, not the selection).
  PoseSampleDepths pose_sample_depths(plan->model, plan->depth_ranges);
  const auto sample_depths = [&](image_t reference) -> std::optional<std::pair<double, double>> {
    if (plan->user_depth_range) {
      return std::make_pair(plan->user_depth_range->d_min, plan->user_depth_range->d_max);
    }
    return pose_sample_depths.For(reference);
  };
  plan->problems = ResolvePatchMatchConfigWithPoseFallback(
      entries, plan->model, options.ViewSelection(), config_path.string(), sample_depths,
      &plan->pose_selected_references);
  plan->guessed_sample_depths = pose_sample_depths.guessed();
}

// Images missing on disk are reported once and dropped from every source
// list; better to learn that now than after hours of inference.
void DropMissingImages(const Workspace& workspace, DensePlan* plan) {
  std::set<image_t> missing;
  for (const auto& [image_id, image] : plan->model.images) {
    if (!std::filesystem::is_regular_file(workspace.ImagePath(image.name))) {
      missing.insert(image_id);
    }
  }
  plan->missing_images.assign(missing.begin(), missing.end());
  for (StereoProblem& problem : plan->problems) {
    auto& sources = problem.source_image_ids;
    sources.erase(std::remove_if(sources.begin(), sources.end(),
                                 [&](image_t id) { return missing.count(id) > 0; }),
                  sources.end());
  }
}

std::string FormatDepth(double depth) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g", depth);
  return buffer;
}

// "a.png, b.png and 3 more": a line stays a line on big workspaces.
std::string NameList(const DensePlan& plan, const std::vector<image_t>& ids) {
  constexpr std::size_t kShown = 5;
  std::string text;
  for (std::size_t i = 0; i < ids.size() && i < kShown; ++i) {
    text += (i == 0 ? "" : ", ") + plan.ImageOf(ids[i]).name;
  }
  if (ids.size() > kShown) text += " and " + std::to_string(ids.size() - kShown) + " more";
  return text;
}

// The references the photometric pass computes a map for: those with at
// least one source whose image file exists.
std::set<image_t> ReferencesWithMaps(const DensePlan& plan) {
  const std::set<image_t> missing(plan.missing_images.begin(), plan.missing_images.end());
  std::set<image_t> ids;
  for (const StereoProblem& problem : plan.problems) {
    if (!problem.source_image_ids.empty() && missing.count(problem.reference_image_id) == 0) {
      ids.insert(problem.reference_image_id);
    }
  }
  return ids;
}

// Distinct sources of `problem` in `with_maps`: a source listed twice is
// still one map to agree with.
int CountSourcesWithMaps(const StereoProblem& problem, const std::set<image_t>& with_maps) {
  const std::set<image_t> sources(problem.source_image_ids.begin(),
                                  problem.source_image_ids.end());
  int count = 0;
  for (image_t source : sources) {
    if (source != problem.reference_image_id && with_maps.count(source) > 0) ++count;
  }
  return count;
}

}  // namespace

void PlanOptions::Check() const {
  if (max_num_src_images < 1) {
    throw std::invalid_argument("--max_num_src_images must be at least 1, got " +
                                std::to_string(max_num_src_images));
  }
  if (static_cast<std::size_t>(max_num_src_images) > kMaxAutoSources) {
    throw std::invalid_argument("--max_num_src_images must be at most " +
                                std::to_string(kMaxAutoSources));
  }
  RequireFinite(min_triangulation_angle, "min_triangulation_angle");
  if (min_triangulation_angle < 0.0 || min_triangulation_angle > 90.0) {
    throw std::invalid_argument("--min_triangulation_angle must be in [0, 90] degrees");
  }
  RequireFinite(depth_min_percentile, "depth_min_percentile");
  RequireFinite(depth_max_percentile, "depth_max_percentile");
  RequireFinite(depth_stretch_ratio, "depth_stretch_ratio");
  if (depth_min_percentile < 0.0 || depth_min_percentile > 1.0 || depth_max_percentile < 0.0 ||
      depth_max_percentile > 1.0) {
    throw std::invalid_argument(
        "--depth_min_percentile and --depth_max_percentile are fractions in [0, 1]");
  }
  if (depth_min_percentile > depth_max_percentile) {
    throw std::invalid_argument("--depth_min_percentile must not exceed --depth_max_percentile");
  }
  if (depth_stretch_ratio < 0.0 || depth_stretch_ratio >= 1.0) {
    throw std::invalid_argument("--depth_stretch_ratio must be in [0, 1)");
  }
  if (depth_min_num_points < 1) {
    throw std::invalid_argument("--depth_min_num_points must be at least 1");
  }
  RequireFinite(depth_min, "depth_min");
  RequireFinite(depth_max, "depth_max");
  if ((depth_min > 0) != (depth_max > 0)) {
    throw std::invalid_argument("--depth_min and --depth_max must be given together");
  }
  if (depth_min > 0 && depth_min >= depth_max) {
    throw std::invalid_argument("--depth_min must be smaller than --depth_max");
  }
  RequireFinite(depth_range_widening, "depth_range_widening");
  if (depth_range_widening < 1.0 || depth_range_widening > 1e6) {
    throw std::invalid_argument("--depth_range_widening must be in [1, 1e6]");
  }
  // The library structs check themselves too; this catches any drift between
  // the two sets of rules.
  ViewSelection().Check();
  DepthRange().Check();
}

ViewSelectionOptions PlanOptions::ViewSelection() const {
  ViewSelectionOptions options;
  options.min_triangulation_angle_deg = min_triangulation_angle;
  return options;
}

DepthRangeOptions PlanOptions::DepthRange() const {
  DepthRangeOptions options;
  options.min_percentile = depth_min_percentile;
  options.max_percentile = depth_max_percentile;
  options.stretch_ratio = depth_stretch_ratio;
  options.min_num_points = static_cast<std::size_t>(depth_min_num_points);
  return options;
}

std::optional<DepthRange> DensePlan::HintFor(image_t image_id, bool* is_fallback) const {
  if (is_fallback != nullptr) *is_fallback = false;
  DepthRange hint;
  if (user_depth_range) {
    hint = *user_depth_range;
  } else if (HasOwnDepthRange(image_id)) {
    hint = depth_ranges.at(image_id);
  } else if (fallback_depth_range.valid) {
    hint = fallback_depth_range;
    if (is_fallback != nullptr) *is_fallback = true;
  } else {
    return std::nullopt;
  }
  if (depth_range_widening != 1.0) {
    hint.d_min /= depth_range_widening;
    hint.d_max *= depth_range_widening;
  }
  return hint;
}

bool DensePlan::HasOwnDepthRange(image_t image_id) const {
  const auto own = depth_ranges.find(image_id);
  return own != depth_ranges.end() && own->second.valid;
}

DensePlan PlanDenseReconstruction(const Workspace& workspace, const PlanOptions& options) {
  options.Check();
  DensePlan plan;
  plan.model = workspace.ReadModel();
  if (plan.model.images.empty()) {
    throw IoError(workspace.SparseDir().string(), "the sparse model has no registered images");
  }
  CheckPinholeCameras(plan.model, workspace);
  plan.depth_ranges = ComputeDepthRanges(plan.model, options.DepthRange());
  plan.fallback_depth_range = FallbackDepthRange(plan.depth_ranges);
  if (options.depth_min > 0) {
    colmap_io::DepthRange user;
    user.d_min = options.depth_min;
    user.d_max = options.depth_max;
    user.valid = true;
    plan.user_depth_range = user;
  }
  plan.depth_range_widening = options.depth_range_widening;
  // After the hints: pose-based source selection samples them.
  PlanProblems(workspace, options, &plan);
  DropMissingImages(workspace, &plan);
  return plan;
}

void RestrictToImages(const std::vector<std::string>& names, DensePlan* plan) {
  std::set<std::string> wanted(names.begin(), names.end());
  std::vector<StereoProblem> kept;
  for (const StereoProblem& problem : plan->problems) {
    if (wanted.erase(plan->ImageOf(problem.reference_image_id).name) > 0) {
      kept.push_back(problem);
    }
  }
  if (!wanted.empty()) {
    throw std::invalid_argument("image \"" + *wanted.begin() +
                                "\" of the image list is not a reference image of the plan");
  }
  plan->problems = std::move(kept);
}

void RestrictToShard(int index, int count, DensePlan* plan) {
  if (count < 1 || index < 0 || index >= count) {
    throw std::invalid_argument("shard index must be in [0, count)");
  }
  std::vector<StereoProblem> kept;
  for (std::size_t i = 0; i < plan->problems.size(); ++i) {
    if (static_cast<int>(i % static_cast<std::size_t>(count)) == index) {
      kept.push_back(plan->problems[i]);
    }
  }
  plan->problems = std::move(kept);
}

void PrintPlan(const DensePlan& plan, std::ostream& out) {
  out << "# " << plan.model.images.size() << " images, " << plan.model.points3D.size()
      << " sparse points; " << plan.problems.size() << " stereo problems from "
      << plan.problems_source << '\n';
  for (image_t missing : plan.missing_images) {
    out << "# warning: image file missing, not used: " << plan.ImageOf(missing).name << '\n';
  }
  const std::string note = WithoutSparsePointsNote(plan);
  if (!note.empty()) out << "# " << note << '\n';
  for (const StereoProblem& problem : plan.problems) {
    const Image& reference = plan.ImageOf(problem.reference_image_id);
    const auto own = plan.depth_ranges.find(problem.reference_image_id);
    bool fallback = false;
    const auto range = plan.HintFor(problem.reference_image_id, &fallback);

    out << reference.name << '\t';
    if (range) {
      out << "d_min=" << FormatDepth(range->d_min) << "\td_max=" << FormatDepth(range->d_max);
    } else {
      out << "d_min=none\td_max=none";
    }
    // The count is the image's own: how much sparse support its range has.
    out << "\tpoints=" << (own != plan.depth_ranges.end() ? own->second.num_points : 0);
    if (plan.user_depth_range) {
      out << "\tuser";
    } else if (fallback) {
      out << "\tfallback";
    }
    if (plan.pose_selected_references.count(problem.reference_image_id) > 0) out << "\tposes";
    out << "\tsources=";
    for (std::size_t i = 0; i < problem.source_image_ids.size(); ++i) {
      out << (i == 0 ? "" : ",") << plan.ImageOf(problem.source_image_ids[i]).name;
    }
    if (problem.source_image_ids.empty()) out << "(none: skipped, as COLMAP does)";
    out << '\n';
  }
}

std::string WithoutSparsePointsNote(const DensePlan& plan) {
  std::vector<image_t> without_own, without_any, from_poses;
  for (const StereoProblem& problem : plan.problems) {
    const image_t id = problem.reference_image_id;
    if (!plan.HasOwnDepthRange(id)) without_own.push_back(id);
    if (!plan.HintFor(id)) without_any.push_back(id);
    if (plan.pose_selected_references.count(id) > 0) from_poses.push_back(id);
  }
  if (without_own.empty() && from_poses.empty()) return "";
  const std::size_t count = plan.problems.size();
  std::string note = "planning without sparse points";
  if (plan.model.points3D.empty()) note += " (the sparse model has no 3-D points)";
  if (!without_own.empty()) {
    note += ": " + std::to_string(without_own.size()) + " of " + std::to_string(count) +
            " reference image(s) see none (" + NameList(plan, without_own) + ")";
    if (plan.user_depth_range) {
      note += "; depth-range hint from --depth_min/--depth_max";
    } else if (without_any.empty()) {
      note += "; their depth-range hint is the union of the other images' ranges";
    } else if (without_any.size() == count) {
      note += "; no depth-range hint (model v2 weights need none)";
    } else {
      note += "; without a depth-range hint: " + NameList(plan, without_any);
    }
  }
  if (!from_poses.empty()) {
    note += "; the __auto__ sources of " + std::to_string(from_poses.size()) +
            " image(s) are chosen from the camera poses (overlap of the viewing frusta";
    if (plan.guessed_sample_depths) {
      note += " sampled at depths " + FormatDepth(plan.guessed_sample_depths->first) + " to " +
              FormatDepth(plan.guessed_sample_depths->second) + ", guessed from the baselines";
    }
    note += ")";
  }
  return note;
}

std::vector<image_t> ReferencesWithoutHint(const DensePlan& plan) {
  std::vector<image_t> ids;
  for (const StereoProblem& problem : plan.problems) {
    if (!problem.source_image_ids.empty() && !plan.HintFor(problem.reference_image_id)) {
      ids.push_back(problem.reference_image_id);
    }
  }
  return ids;
}

int NumSourcesWithMaps(const DensePlan& plan, const StereoProblem& problem) {
  return CountSourcesWithMaps(problem, ReferencesWithMaps(plan));
}

std::string PlanMinConsistentViews(int min_consistent_views, bool user_set, DensePlan* plan) {
  plan->min_consistent_views.clear();
  const std::set<image_t> with_maps = ReferencesWithMaps(*plan);
  // The references short of sources, in plan order, with what they have.
  std::vector<image_t> short_ids;
  std::map<image_t, int> available;
  int most = 0;
  std::set<image_t> seen;
  for (const StereoProblem& problem : plan->problems) {
    const image_t id = problem.reference_image_id;
    if (with_maps.count(id) == 0 || !seen.insert(id).second) continue;
    const int count = CountSourcesWithMaps(problem, with_maps);
    most = std::max(most, count);
    if (count < min_consistent_views) {
      short_ids.push_back(id);
      available[id] = count;
    }
  }
  if (short_ids.empty()) return "";
  const std::string required = std::to_string(min_consistent_views);
  const std::string affected = std::to_string(short_ids.size()) + " of " +
                               std::to_string(with_maps.size()) + " reference image(s)";
  // Only 0 keeps anything then, and that is no consistency check: not a
  // value to choose for the user.
  if (most == 0) {
    throw std::invalid_argument(
        "no reference image has a source view with a depth map of its own (a source gets one "
        "only as a reference image with sources of its own in patch-match.cfg), so the "
        "geometric filter and fusion would keep no pixel at --min_num_consistent " +
        required +
        "; list the sources as reference images too, pass --min_num_consistent 0 to fuse the "
        "depths unchecked, or use --mode photometric for the depth maps alone");
  }
  if (user_set && short_ids.size() == with_maps.size()) {
    throw std::invalid_argument(
        "--min_num_consistent " + required +
        " cannot be met: no reference image has that many source views with depth maps (at "
        "most " + std::to_string(most) + (most == 1 ? ", as in a stereo pair" : "") +
        "), so the geometric filter and fusion would keep no pixel; pass --min_num_consistent " +
        std::to_string(most) + " or less, or leave it out: the default adapts to the sources "
        "available");
  }
  if (user_set) {
    return "--min_num_consistent " + required + ": " + affected +
           " have fewer source views with depth maps (" + NameList(*plan, short_ids) +
           ") and will keep no pixel; a lower value keeps them";
  }
  int lowest = min_consistent_views, highest = 0, without_any = 0;
  for (image_t id : short_ids) {
    // At least 1: agreement with nothing is no check at all.
    const int used = std::max(1, available[id]);
    plan->min_consistent_views[id] = used;
    lowest = std::min(lowest, used);
    highest = std::max(highest, used);
    if (available[id] == 0) ++without_any;
  }
  std::string warning = "--min_num_consistent is " + required + " by default, but " + affected +
                        " have fewer source views with depth maps (" +
                        NameList(*plan, short_ids) + "): using " + std::to_string(lowest);
  if (highest != lowest) warning += " to " + std::to_string(highest) + " (what each has)";
  warning += " for them";
  if (without_any > 0) {
    warning += "; " + std::to_string(without_any) +
               " of them have no source with a depth map (their sources are not reference "
               "images with sources) and keep no pixel";
  }
  return warning + "; pass --min_num_consistent to choose the value yourself";
}

void CheckHintsForWeights(const DensePlan& plan, const std::vector<image_t>& without,
                          bool weights_need_depth_range) {
  if (!weights_need_depth_range || without.empty()) return;
  throw std::invalid_argument(
      "no depth-range hint for " + std::to_string(without.size()) + " reference image(s) (" +
      NameList(plan, without) +
      "): no image sees sparse points to derive one from, and these weights (init = "
      "random, the paper's) draw their initialisation inside it; pass --depth_min and "
      "--depth_max (the scene's depth range in the model's units; a rough, wide one is "
      "enough), or use model v2 weights (init = match), which need no hint");
}

}  // namespace dispmvs::dense
