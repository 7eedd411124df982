// dispmvs_colmap: DispMVS dense reconstruction for a COLMAP dense workspace
// (the folder `colmap image_undistorter` writes).
//
// The program is organised as the dense MVS step it will become: parse and
// check Options, open the workspace, plan the stereo problems (reference
// image, source images, depth-range hint), then run the passes. Today only
// the planning exists and the plan is printed; the photometric pass (network
// inference), the geometric pass (multi-view consistency filtering) and the
// fusion are later steps that consume the same DensePlan.
//
// Errors of any kind are printed as "error: <message>" on stderr with exit
// status 1.

#include <boost/program_options.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "colmap_io/depth_range.h"
#include "colmap_io/error.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/view_selection.h"
#include "colmap_io/workspace.h"

namespace {

namespace po = boost::program_options;
using namespace dispmvs::colmap_io;

constexpr const char* kDescription = R"(dispmvs_colmap: DispMVS dense reconstruction for a COLMAP workspace.

Reads a dense workspace as written by `colmap image_undistorter`
(WORKSPACE/images, WORKSPACE/sparse, WORKSPACE/stereo) and plans one stereo
problem per reference image: its source views and its depth-range hint.

Source views come from WORKSPACE/stereo/patch-match.cfg when it exists
(`__auto__, N`, `__all__` or an explicit list per reference image, as in
COLMAP); without it, every image of the sparse model is a reference with
`__auto__` selection. `__auto__` keeps the images whose triangulation angle
with the reference reaches --min_triangulation_angle and takes those sharing
the most sparse points, at most min(N, --max_num_src_images) of them.

The depth range of an image comes from the sparse points it sees (robust
percentiles widened by a stretch ratio, as COLMAP computes it). DispMVS uses it
only as a hint for its random initialisation: nothing is clipped to it. Images
seeing fewer than --depth_min_num_points points get the union of the other
images' ranges (marked "fallback").

This version prints the plan, one tab-separated line per reference image:
  NAME  d_min=..  d_max=..  points=..  [fallback]  sources=NAME1,NAME2,...
Depth-map estimation and fusion are not implemented yet.

Options)";

// Everything the command line controls. Check() validates the values before
// any work starts, naming the option at fault.
struct Options {
  std::string workspace_path;
  // DispMVS was trained and evaluated on DTU and BlendedMVS with N = 5 views,
  // i.e. one reference and 4 sources (paper, Sec. 4). More sources cost GPU
  // memory linearly and the network never saw them; COLMAP's own `__auto__, 20`
  // is tuned for PatchMatch, which benefits from many more views.
  int max_num_src_images = 4;
  // COLMAP's PatchMatchStereo.min_triangulation_angle default, degrees.
  double min_triangulation_angle = 1.0;
  // Depth-range hint, see colmap_io/depth_range.h (defaults are COLMAP's).
  double depth_min_percentile = 0.01;
  double depth_max_percentile = 0.99;
  double depth_stretch_ratio = 0.25;
  int depth_min_num_points = 1;

  // Throws std::invalid_argument naming the command-line option.
  void Check() const;

  ViewSelectionOptions ViewSelection() const;
  DepthRangeOptions DepthRange() const;
};

void RequireFinite(double value, const char* option) {
  if (!std::isfinite(value)) {
    throw std::invalid_argument(std::string("--") + option + " must be a finite number");
  }
}

void Options::Check() const {
  if (workspace_path.empty()) throw std::invalid_argument("--workspace_path must not be empty");
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
  // The library structs check themselves too; this catches any drift between
  // the two sets of rules.
  ViewSelection().Check();
  DepthRange().Check();
}

ViewSelectionOptions Options::ViewSelection() const {
  ViewSelectionOptions options;
  options.min_triangulation_angle_deg = min_triangulation_angle;
  return options;
}

DepthRangeOptions Options::DepthRange() const {
  DepthRangeOptions options;
  options.min_percentile = depth_min_percentile;
  options.max_percentile = depth_max_percentile;
  options.stretch_ratio = depth_stretch_ratio;
  options.min_num_points = static_cast<std::size_t>(depth_min_num_points);
  return options;
}

// Parses the command line. Returns nothing when --help was given (the help
// has then been printed); throws on unknown options or malformed values.
std::optional<Options> ParseCommandLine(int argc, char** argv) {
  Options options;
  po::options_description description(kDescription);
  description.add_options()
      ("help,h", "Print this help and exit.")
      ("workspace_path", po::value<std::string>(&options.workspace_path),
       "COLMAP dense workspace (required): the output folder of image_undistorter.")
      ("max_num_src_images",
       po::value<int>(&options.max_num_src_images)->default_value(options.max_num_src_images),
       "Most source views per reference image for `__auto__` selection (N = 5 views "
       "in total, as DispMVS was trained). `__all__` and explicit lists in "
       "patch-match.cfg are used as written.")
      ("min_triangulation_angle",
       po::value<double>(&options.min_triangulation_angle)
           ->default_value(options.min_triangulation_angle, "1"),
       "Degrees; `__auto__` ignores source views whose triangulation angle with the "
       "reference (75th percentile over shared points) is smaller.")
      ("depth_min_percentile",
       po::value<double>(&options.depth_min_percentile)
           ->default_value(options.depth_min_percentile, "0.01"),
       "Fraction in [0, 1]: the percentile of the sparse depths taken as the low end "
       "of the depth-range hint.")
      ("depth_max_percentile",
       po::value<double>(&options.depth_max_percentile)
           ->default_value(options.depth_max_percentile, "0.99"),
       "Fraction in [0, 1]: the percentile taken as the high end.")
      ("depth_stretch_ratio",
       po::value<double>(&options.depth_stretch_ratio)
           ->default_value(options.depth_stretch_ratio, "0.25"),
       "In [0, 1): the hint is [(1 - s) * low, (1 + s) * high].")
      ("depth_min_num_points",
       po::value<int>(&options.depth_min_num_points)
           ->default_value(options.depth_min_num_points),
       "Images seeing fewer sparse points use the fallback range.");

  po::variables_map values;
  po::store(po::parse_command_line(argc, argv, description), values);
  // --help wins over everything else, including missing required options.
  if (values.count("help") > 0) {
    std::cout << description << '\n';
    return std::nullopt;
  }
  po::notify(values);
  if (values.count("workspace_path") == 0) {
    throw std::invalid_argument("--workspace_path is required (see --help)");
  }
  options.Check();
  return options;
}

// What the dense step will work on. Built once, used by every pass.
struct DensePlan {
  SparseModel model;
  // Where the problems came from: the patch-match.cfg path, or a note that
  // they were generated.
  std::string problems_source;
  std::vector<StereoProblem> problems;
  std::map<image_t, DepthRange> depth_ranges;  // every image of the model
  DepthRange fallback_depth_range;
};

// Dense MVS needs undistorted images: pinhole cameras only.
void CheckPinholeCameras(const SparseModel& model, const Workspace& workspace) {
  for (const auto& [image_id, image] : model.images) {
    const auto camera = model.cameras.find(image.camera_id);
    if (camera == model.cameras.end() || !camera->second.IsPinhole()) {
      throw IoError(workspace.SparseDir().string(),
                    "image \"" + image.name +
                        "\" does not use a PINHOLE or SIMPLE_PINHOLE camera; dense "
                        "reconstruction needs the output of `colmap image_undistorter`");
    }
  }
}

// The stereo problems: from patch-match.cfg, or `__auto__` for every image.
// Applies --max_num_src_images to `__auto__` entries.
void PlanProblems(const Workspace& workspace, const Options& options, DensePlan* plan) {
  const std::filesystem::path config_path = workspace.PatchMatchConfigPath();
  std::vector<PatchMatchEntry> entries;
  if (std::filesystem::exists(config_path)) {
    entries = ReadPatchMatchConfig(config_path);
    plan->problems_source = config_path.string();
  } else {
    entries = AutoPatchMatchConfig(plan->model, static_cast<std::size_t>(options.max_num_src_images));
    plan->problems_source = "no patch-match.cfg: __auto__, " +
                            std::to_string(options.max_num_src_images) + " for every image";
  }
  for (PatchMatchEntry& entry : entries) {
    if (entry.sources.kind == SourceSpec::Kind::kAuto) {
      entry.sources.max_num_sources = std::min(
          entry.sources.max_num_sources, static_cast<std::size_t>(options.max_num_src_images));
    }
  }
  plan->problems = ResolvePatchMatchConfig(entries, plan->model, options.ViewSelection(),
                                           config_path.string());
}

// Every image the plan touches must be on disk; better to learn that now
// than after hours of inference.
void CheckImagesExist(const Workspace& workspace, const DensePlan& plan) {
  std::vector<image_t> needed;
  for (const StereoProblem& problem : plan.problems) {
    if (problem.source_image_ids.empty()) continue;  // skipped, see PrintPlan
    needed.push_back(problem.reference_image_id);
    needed.insert(needed.end(), problem.source_image_ids.begin(), problem.source_image_ids.end());
  }
  for (image_t image_id : needed) {
    const std::filesystem::path path = workspace.ImagePath(plan.model.images.at(image_id).name);
    if (!std::filesystem::is_regular_file(path)) {
      throw IoError(path.string(), "image file of the sparse model is missing");
    }
  }
}

DensePlan PlanDenseReconstruction(const Workspace& workspace, const Options& options) {
  DensePlan plan;
  plan.model = workspace.ReadModel();
  CheckPinholeCameras(plan.model, workspace);
  PlanProblems(workspace, options, &plan);
  CheckImagesExist(workspace, plan);
  plan.depth_ranges = ComputeDepthRanges(plan.model, options.DepthRange());
  plan.fallback_depth_range = FallbackDepthRange(plan.depth_ranges);
  return plan;
}

std::string FormatDepth(double depth) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g", depth);
  return buffer;
}

void PrintPlan(const DensePlan& plan, std::ostream& out) {
  out << "# " << plan.model.images.size() << " images, " << plan.model.points3D.size()
      << " sparse points; " << plan.problems.size() << " stereo problems from "
      << plan.problems_source << '\n';
  for (const StereoProblem& problem : plan.problems) {
    const Image& reference = plan.model.images.at(problem.reference_image_id);
    const DepthRange& own_range = plan.depth_ranges.at(problem.reference_image_id);
    const bool use_fallback = !own_range.valid;
    const DepthRange& range = use_fallback ? plan.fallback_depth_range : own_range;

    out << reference.name << '\t';
    if (range.valid) {
      out << "d_min=" << FormatDepth(range.d_min) << "\td_max=" << FormatDepth(range.d_max);
    } else {
      out << "d_min=none\td_max=none";
    }
    // The count is the image's own: how much sparse support its range has.
    out << "\tpoints=" << own_range.num_points;
    if (use_fallback) out << "\tfallback";
    out << "\tsources=";
    for (std::size_t i = 0; i < problem.source_image_ids.size(); ++i) {
      out << (i == 0 ? "" : ",") << plan.model.images.at(problem.source_image_ids[i]).name;
    }
    if (problem.source_image_ids.empty()) out << "(none: skipped, as COLMAP does)";
    out << '\n';
  }
}

int Run(const Options& options) {
  const Workspace workspace(options.workspace_path);
  const DensePlan plan = PlanDenseReconstruction(workspace, options);
  PrintPlan(plan, std::cout);
  // Later: RunPhotometricPass(workspace, plan, options) writes
  // dispmvs.photometric depth/confidence maps, RunGeometricPass filters them
  // into dispmvs.geometric, RunFusion writes fused.ply.
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const std::optional<Options> options = ParseCommandLine(argc, argv);
    if (!options) return 0;
    return Run(*options);
  } catch (const std::exception& error) {
    std::cerr << "error: " << error.what() << '\n';
    return 1;
  } catch (...) {
    std::cerr << "error: unknown exception\n";
    return 1;
  }
}
