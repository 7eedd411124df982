// dispmvs_eval: scores the depth maps of a COLMAP dense workspace (ours,
// PatchMatch's, any TYPE) against ground-truth depth maps, and point clouds
// against a ground-truth cloud. See eval/workspace_eval.h for the layout and
// eval/report.h for the output. Errors print one line "error: <message>" on
// stderr with exit status 1; so does a table that misses views dispmvs_colmap
// failed on (a "warning:" line per view after the table, with the reason).

#include <boost/program_options.hpp>

#include <exception>
#include <iostream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "colmap_io/stereo_config.h"
#include "eval/comparison_report.h"
#include "eval/method_comparison.h"
#include "eval/report.h"
#include "eval/workspace_eval.h"
#include "src/program_main.h"
#include "src/program_options.h"

namespace {

namespace po = boost::program_options;
using namespace dispmvs;

constexpr const char* kDescription = R"(dispmvs_eval: depth-map and point-cloud accuracy against ground truth.

Usage: dispmvs_eval --workspace_path WS [--types T1,T2,...] [--ply FILE ...]
                    [--json OUT.json] [--tsv OUT.tsv] [--png_dir DIR] [--per_view]
                    [options]
       dispmvs_eval --workspace_path WS --compare TYPE_A,TYPE_B
                    [--compare_ply A.ply,B.ply] [--json OUT.json] [--per_view]

Without ground truth (--compare), two methods' maps in one workspace, e.g.
ours against PatchMatch's (dispmvs.geometric,geometric), per view and pooled
over the pixels of the views both have: coverage of each; pixels both have;
agreement, the shared pixels within 1 / 2 / 5 % of each other
(2 |a - b| / (a + b)); and each method's own multi-view consistency, the
share of its valid pixels that at least one source view's map of the same
method agrees with (reprojection within 1 px and depth within 1 %, the test
fusion applies; sources from patch-match.cfg, else __auto__, 4, N of
`__auto__, N` capped at --max_num_src_images, from the camera poses where no
sparse point is shared, as dispmvs_colmap chooses them). With
--compare_ply, the clouds too: mean distance A -> B and B -> A, and the
shares of each within tau of the other, tau and the cut-off as fractions of
B's bounding-box diagonal (--tau_rel, --cutoff_rel).

WS is a COLMAP dense workspace (WS/sparse with PINHOLE or SIMPLE_PINHOLE
cameras, WS/images, WS/stereo/depth_maps/NAME.TYPE.bin) with ground truth:
  WS/ground_truth/depth_maps/NAME.bin   GT depth per image (COLMAP dense array,
                                        image size, 0 = no surface)
  WS/ground_truth/points.ply            optional GT cloud (fused.ply layout)

Depth maps (one table row per TYPE, e.g. dispmvs.geometric, geometric): over
the GT pixels (finite, > 0), a prediction is valid when finite and > 0.
  coverage   predicted GT pixels / GT pixels
  abs_rel    mean |d - gt| / gt over the predicted pixels
  med_rel    median |d - gt| / gt over the predicted pixels (from a log
             histogram: within 0.12 % of the exact median, exact when the
             errors near the median are equal)
  <X%pred    predicted pixels with |d - gt| / gt < X %, of the predicted ones
  <X%all     the same count, of all GT pixels (a missing prediction = miss)
Overall rows weight every pixel equally; views = maps found / images with GT.

Rectified stereo pairs: an image with GT whose camera and another registered
image's form a rectified pair (same rotation within 1e-9 per matrix entry,
camera centres apart along the camera x-axis only (y, z below 1e-9 of the
baseline B), equal fx, fy and cy, PINHOLE or SIMPLE_PINHOLE; the shortest
baseline if several) is also scored in disparity, in pixels of the GT's
resolution: error |f B / d - f B / gt| (f = fx at the GT's size; doffs cancels).
Five columns are then added (only when some image has such a partner):
  disp_err   mean disparity error over the predicted pixels, pixels
  <Npxpred   predicted pixels with disparity error < N px (N = 1, 2)
  <Npxall    the same count, of all GT pixels
with "n/a" for views without a partner.
Maps smaller than the GT (max_image_size) are compared at their own size,
sampling the GT at the nearest pixel of the same position in COLMAP's dense
convention: map pixel (col, row) of a map scaled by s = map size / image size
is image position (col / s, row / s), raw indices, no half-pixel shift. The
map must be the GT scaled by one factor with rounded sides.

Point clouds (--ply, fused.ply layout; one row each), against
WS/ground_truth/points.ply, or without it the GT depth maps back-projected
(X = R^T (d K^-1 (col / s, row / s, 1) - t), every --gt_stride-th pixel;
GT maps are read in COLMAP's dense indexing, as dispmvs_synth writes them):
  accuracy      mean distance reconstruction -> nearest GT point
  completeness  mean distance GT -> nearest reconstructed point
                (both ignore distances >= cut-off: acc_cut / comp_cut count them)
  overall       (accuracy + completeness) / 2
  precision     reconstructed points within tau of the GT (all points count)
  recall        GT points within tau of the reconstruction
  F-score       2 precision recall / (precision + recall)
Distances are in scene units; tau and the cut-off default to fractions of the
GT cloud's bounding-box diagonal (--tau_rel, --cutoff_rel).

--png_dir DIR writes, per image with GT, DIR/NAME.gt.png (GT depth) and per
TYPE DIR/NAME.TYPE.depth.png (same colour scale as the view's GT: its min
depth blue to its max red, no depth black) and DIR/NAME.TYPE.error.png
(relative error 0 blue to --png_max_error and above red; GT without a
prediction white; no GT black). Files are written atomically.

Views dispmvs_colmap failed on (a damaged image, say) have no dispmvs.* map;
their run recorded why (WS/stereo/dispmvs_records/NAME.txt). Each is named
after the table with that reason ("warning: NAME has no TYPE map: ..."), and
the exit status is then 1: the numbers above leave those views out.

--regions splits each TYPE's pixels by where they lie, from the ground
truth alone: seen by another view with GT (its point inside that view, not
behind that view's GT surface by more than 3 %; a hole in that GT counts as
seen), hidden (inside another
view, but behind a nearer surface in all of them), outside every other view;
and the seen ones by their distance (pixels along rows and columns) to the
nearest GT depth edge (neighbours whose depths differ by more than about
5 %): 0-1, 2-3, 4-6, 7-12, 13+. Per region: its share of the GT pixels and
the share of its pixels within 1 / 2 / 5 % (missing = miss). In a two-view
pair it says what the second view lets a matcher see; it reads every GT map
first and keeps them in memory.

--tsv FILE writes a summary for scripts that add up many workspaces exactly:
tab-separated, '#' lines are comments, a '#' header line with the column
names before each kind of record, then one record per depth TYPE
  depth TYPE views gt_pixels predicted within_1 within_2 within_5 abs_rel_sum
        disparity_gt_pixels disparity_within_1px disparity_within_2px
(integer pixel counts summed over the type's views; abs_rel_sum = sum of
|d - gt| / gt over the predicted pixels, %.17g; disparity counts 0 where no
view has a rectified partner) and one record per --ply
  cloud PLY points gt_points accuracy completeness overall precision recall
        fscore tau cutoff
(%.17g, "nan" for NaN), and with --regions one record per TYPE and region
  region TYPE REGION gt_pixels within_1 within_2 within_5. E.g. <2%all over workspaces:
  awk -F'\t' '$1 == "depth" && $2 == T { g += $4; w += $7 } END { print w / g }' T=dispmvs.geometric */eval.tsv

Options)";

struct Options {
  std::string workspace_path;
  std::string compare;      // "TYPE_A,TYPE_B": method against method, no ground truth
  std::string compare_ply;  // "A.ply,B.ply"
  int max_num_src_images = colmap_io::kDefaultMaxNumSourceImages;  // --compare only
  std::string types;
  std::string json_path;
  std::string tsv_path;
  bool per_view = false;
  eval::WorkspaceEvalOptions eval;
};

std::vector<std::string> SplitTypes(const std::string& text) {
  std::vector<std::string> types;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    const auto begin = item.find_first_not_of(" \t");
    const auto end = item.find_last_not_of(" \t");
    if (begin == std::string::npos) {
      throw std::invalid_argument("--types has an empty entry: '" + text + "'");
    }
    types.push_back(item.substr(begin, end - begin + 1));
  }
  if (types.empty() || (!text.empty() && text.back() == ',')) {
    throw std::invalid_argument("--types has an empty entry: '" + text + "'");
  }
  return types;
}

std::optional<Options> ParseCommandLine(int argc, char** argv) {
  Options o;
  po::options_description description(kDescription);
  // clang-format off
  description.add_options()
      ("help,h", "Print this help and exit.")
      ("workspace_path", po::value<std::string>(&o.workspace_path),
       "Workspace (required), with ground truth unless --compare.")
      ("compare", po::value<std::string>(&o.compare),
       "TYPE_A,TYPE_B: compare two methods' depth maps without ground truth (see above), "
       "e.g. dispmvs.geometric,geometric for ours against PatchMatch's.")
      ("compare_ply", po::value<std::string>(&o.compare_ply),
       "A.ply,B.ply: with --compare, also the two fused clouds, each against the other.")
      ("max_num_src_images", po::value<int>(&o.max_num_src_images)->default_value(o.max_num_src_images),
       "With --compare: at most this many `__auto__` sources per view for the consistency "
       "test; pass the value the dispmvs_colmap run used (its option of the same name).")
      ("types", po::value<std::string>(&o.types),
       "Comma-separated depth-map TYPEs, e.g. dispmvs.geometric,geometric; default: every "
       "TYPE found under WS/stereo/depth_maps. A TYPE without maps is reported as such.")
      ("ply", po::value<std::vector<std::string>>(&o.eval.ply_paths)->multitoken()->composing(),
       "Point cloud(s) to evaluate (binary PLY as written by stereo_fusion / dispmvs_colmap), "
       "e.g. WS/fused.ply; repeat or list several.")
      ("json", po::value<std::string>(&o.json_path),
       "Also write every number (unrounded, per view too) to this JSON file.")
      ("tsv", po::value<std::string>(&o.tsv_path),
       "Also write the summary above (pixel counts and sums per TYPE, one record per cloud) "
       "to this tab-separated file.")
      ("png_dir", po::value<std::string>(&o.eval.png_dir),
       "Write colourised depth and relative-error PNGs here (see above).")
      ("per_view", po::bool_switch(&o.per_view), "Print one row per view under each TYPE.")
      ("regions", po::bool_switch(&o.eval.regions),
       "Split each TYPE's pixels by visibility in the other views and distance to a depth edge (see above).")
      ("tau", po::value<double>(&o.eval.tau)->default_value(0),
       "Precision/recall threshold in scene units; 0 = --tau_rel x GT diagonal.")
      ("cutoff", po::value<double>(&o.eval.cutoff)->default_value(0),
       "Outlier cut-off of accuracy/completeness in scene units; 0 = --cutoff_rel x GT "
       "diagonal.")
      ("tau_rel", po::value<double>(&o.eval.tau_relative)->default_value(0.002, "0.002"),
       "Default tau as a fraction of the GT cloud's bounding-box diagonal.")
      ("cutoff_rel", po::value<double>(&o.eval.cutoff_relative)->default_value(0.02, "0.02"),
       "Default cut-off as a fraction of the diagonal.")
      ("gt_stride", po::value<int>(&o.eval.gt_stride)->default_value(1),
       "Without WS/ground_truth/points.ply: back-project every N-th column and row of the GT "
       "depth maps.")
      ("png_max_error", po::value<double>(&o.eval.png_max_rel_error)->default_value(0.05, "0.05"),
       "Relative error at the top of the error PNGs' colour scale.");
  // clang-format on

  po::variables_map values;
  if (!cli::ParseCommandLine(argc, argv, description, &values)) return std::nullopt;
  if (values.count("workspace_path") == 0 || o.workspace_path.empty()) {
    throw std::invalid_argument("--workspace_path is required (see --help)");
  }
  for (const char* option : {"compare_ply", "max_num_src_images"}) {
    if (values.count(option) > 0 && !values[option].defaulted() && values.count("compare") == 0) {
      throw std::invalid_argument(std::string("--") + option + " needs --compare");
    }
  }
  if (values.count("compare") > 0) {
    for (const char* other : {"types", "ply", "tsv", "png_dir", "regions"}) {
      if (values.count(other) > 0 && !values[other].defaulted()) {
        throw std::invalid_argument(std::string("--") + other +
                                    " scores against ground truth; --compare does not use it");
      }
    }
  }
  if (values.count("types") > 0) o.eval.types = SplitTypes(o.types);
  if (values.count("json") > 0 && o.json_path.empty()) {
    throw std::invalid_argument("--json needs a file name");
  }
  if (values.count("tsv") > 0) {
    if (o.tsv_path.empty()) throw std::invalid_argument("--tsv needs a file name");
    // Refused here rather than after a long evaluation.
    for (const std::string& ply : o.eval.ply_paths) {
      if (ply.find_first_of("\t\n\r") != std::string::npos) {
        throw std::invalid_argument("--ply \"" + ply +
                                    "\" contains a tab or a line break, which --tsv cannot hold");
      }
    }
  }
  // Name the options rather than the fields.
  if (!(o.eval.tau >= 0)) throw std::invalid_argument("--tau must be >= 0");
  if (!(o.eval.cutoff >= 0)) throw std::invalid_argument("--cutoff must be >= 0");
  if (!(o.eval.tau_relative > 0)) throw std::invalid_argument("--tau_rel must be > 0");
  if (!(o.eval.cutoff_relative > 0)) throw std::invalid_argument("--cutoff_rel must be > 0");
  if (o.eval.gt_stride < 1) throw std::invalid_argument("--gt_stride must be >= 1");
  if (!(o.eval.png_max_rel_error > 0)) throw std::invalid_argument("--png_max_error must be > 0");
  o.eval.Check();
  return o;
}

// The list "A,B" of --compare or --compare_ply: exactly two entries.
std::pair<std::string, std::string> SplitPair(const std::string& text, const char* option) {
  std::vector<std::string> items;
  try {
    items = SplitTypes(text);
  } catch (const std::invalid_argument&) {
  }
  if (items.size() != 2) {
    throw std::invalid_argument(std::string("--") + option + " needs two entries A,B, got '" +
                                text + "'");
  }
  return {items[0], items[1]};
}

int RunComparison(const Options& options) {
  eval::MethodComparisonOptions compare;
  std::tie(compare.type_a, compare.type_b) = SplitPair(options.compare, "compare");
  if (!options.compare_ply.empty()) {
    std::tie(compare.ply_a, compare.ply_b) = SplitPair(options.compare_ply, "compare_ply");
  }
  compare.max_num_src_images = options.max_num_src_images;
  compare.tau_relative = options.eval.tau_relative;
  compare.cutoff_relative = options.eval.cutoff_relative;
  const eval::MethodComparison report = eval::CompareMethods(options.workspace_path, compare);
  eval::PrintComparison(report, options.per_view, std::cout);
  if (!options.json_path.empty()) {
    eval::WriteComparisonJson(report, options.json_path);
    std::cout << "json: " << options.json_path << '\n';
  }
  return 0;
}

int Run(const Options& options) {
  if (!options.compare.empty()) return RunComparison(options);
  const eval::WorkspaceEvalReport report =
      eval::EvaluateWorkspace(options.workspace_path, options.eval);
  eval::PrintReport(report, options.per_view, std::cout);
  if (!options.eval.png_dir.empty()) {
    std::cout << "png: " << report.png_files << " file(s) in " << options.eval.png_dir << '\n';
  }
  if (!options.json_path.empty()) {
    eval::WriteJsonReport(report, options.json_path);
    std::cout << "json: " << options.json_path << '\n';
  }
  if (!options.tsv_path.empty()) {
    eval::WriteTsvReport(report, options.tsv_path);
    std::cout << "tsv: " << options.tsv_path << '\n';
  }
  // Views the run failed on are missing from the table: an incomplete
  // evaluation, said after it and in the exit status.
  int status = 0;
  for (const eval::TypeDepthResult& type : report.types) {
    for (const eval::TypeDepthResult::FailedView& failed : type.failed_views) {
      std::cout << "warning: " << failed.image_name << " has no " << type.type
                << " map: dispmvs_colmap failed on it: " << failed.reason << '\n';
      status = 1;
    }
  }
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&] {
    const std::optional<Options> options = ParseCommandLine(argc, argv);
    return options ? Run(*options) : 0;
  });
}
