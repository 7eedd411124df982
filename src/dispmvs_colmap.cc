// dispmvs_colmap: DispMVS dense reconstruction for a COLMAP dense workspace
// (the folder `colmap image_undistorter` writes), in place of
// `colmap patch_match_stereo` + `colmap stereo_fusion`.
//
// Parse and check Options, plan the stereo problems (dense_plan.h), then run
// the passes (dense_passes.h). Errors that stop the run print
// "error: <message>" on stderr with exit status 1; a view that fails is
// reported, the others go on, and the exit status is 1 at the end.

#include <boost/program_options.hpp>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"
#include "colmap_io/workspace.h"
#include "fusion/bounding_box.h"
#include "fusion/point_fusion.h"
#include "dense/colmap_export.h"
#include "dense/fusion_pass.h"
#include "dense/geometric_pass.h"
#include "dense/image_masks.h"
#include "dense/photometric_pass.h"
#include "dense/plan.h"
#include "dense/depth_estimator.h"
#include "dense/workspace_maps.h"
#include "eval/html_report.h"
#include "src/program_main.h"
#include "src/shipped_model.h"
#include "src/program_options.h"

namespace {

// A default shown in --help as a person writes it (0.2, not the double's
// 17 digits).
std::string FormatDefault(double value) {
  std::ostringstream text;
  text << value;
  return text.str();
}

namespace fs = std::filesystem;
namespace po = boost::program_options;
using namespace dispmvs;

constexpr const char* kDescription = R"(dispmvs_colmap: DispMVS dense reconstruction for a COLMAP workspace.

Usage: dispmvs_colmap --workspace_path WS [options]

WS is a dense workspace as written by `colmap image_undistorter` (WS/images,
WS/sparse, WS/stereo). Images may be PNG, JPEG, TIFF, BMP, PNM or WebP of their
camera's size, checked on their headers before decoding; a missing or damaged
one fails its own view (with the reason, exit status 1) and is left out as a
source of the others. The default mode runs three passes, like
`colmap patch_match_stereo` followed by `colmap stereo_fusion`:
  1. photometric: the DispMVS network per reference image of
     WS/stereo/patch-match.cfg (without it: every image, `__auto__`
     selection) -> WS/stereo/{depth,normal,confidence}_maps/NAME.dispmvs.photometric.bin
  2. geometric: multi-view geometric-consistency filtering of those maps
     -> NAME.dispmvs.geometric.bin (0 = filtered out)
  3. fusion: consistent pixels averaged -> fused.ply + fused.ply.vis, which
     COLMAP's poisson_mesher and delaunay_mesher accept.
PatchMatch's maps (NAME.photometric.bin, NAME.geometric.bin) are never
touched. Views whose photometric maps exist are skipped (resume after an
interruption; --overwrite recomputes); files are written under a temporary
name and renamed, so an interrupted run leaves no half-written file. Several
processes may share a workspace (--shard K/N, run at once): each view is
claimed with a lock in WS/stereo/dispmvs_claims/ while it is computed, so a
view another process is computing is skipped and said so. The geometric pass
and fusion write shared outputs, so one process at a time runs them (a lock
on WS/stereo/dispmvs_fusion.lock; another stops with an error), and it first
removes the temporary files that killed runs left beside those outputs. Each
computed view's time goes to WS/stereo/dispmvs_records/NAME.txt, which the
run report (WS/dispmvs_report.html) shows. examples/slurm/ runs the shards
on a Slurm cluster (a job array, then a dependent fusion job).

Depth range: each image's range comes from the sparse points it sees (COLMAP's
percentiles and margin; an image seeing none takes the union of the others'),
or from --depth_min/--depth_max. It is only a hint: nothing outside it is
clipped or dropped. The paper's weights (init = random, the shipped ones)
draw their initialisation inside it, so they need one; model v2 weights
(init = match) start from the best match along each epipolar line and need
none. A workspace with no sparse points at all (a model from known poses)
therefore works as it is with v2 weights, and with --depth_min/--depth_max
with the others (without them the run stops before any work).

Source views: `__auto__, N` takes COLMAP's rule, the N images sharing the
most sparse points with the reference at a triangulation angle of at least
--min_triangulation_angle. A reference sharing no sparse point with any image
gets its sources from the camera poses instead: reference pixels are
back-projected to depths inside its hint (without one: 2 to 100 times the
typical distance between neighbouring cameras), and the images seeing most of
these samples, turned at most 60 degrees from the reference and at the same
minimum triangulation angle, are taken. `--mode plan` marks them "poses" and
shows "d_min=none" for images without a hint. Explicit lists and `__all__`
in patch-match.cfg are used as written.

Modes (--mode):
  full         photometric, geometric and fusion (default)
  photometric  the network only, e.g. one shard of a batch job (--shard)
  fuse         geometric filtering + fusion of existing photometric maps,
               e.g. with other thresholds
  export       copy our maps under COLMAP's names into --export_path, a
               sibling workspace linking to WS's images and sparse model, for
               `colmap stereo_fusion --input_type geometric|photometric`
  plan         print the plan (one line per reference image) and stop

Options)";

struct Options {
  std::string workspace_path;
  std::string mode = "full";
  dense::PlanOptions plan;
  dense::PhotometricOptions photometric;
  // The consistency rule of fusion (COLMAP's StereoFusion thresholds), whose
  // sources and confidence (--min_num_consistent, --min_confidence) the
  // geometric pass shares.
  fusion::GeometricFilterOptions filter;
  // The geometric pass's own thresholds and support rule (--filter_*).
  fusion::GeometricFilterOptions geometric = fusion::SupportFilterDefaults();
  // COLMAP's StereoFusion options beyond the consistency rule (the rule is
  // `filter`, copied in by FusionOptions()).
  fusion::FusionOptions fusion;
  std::string mask_path;  // empty: no masks
  std::string bbox_path;  // empty: no box
  std::string output_path;  // default WS/fused.ply
  std::string export_path;
  std::string image_list_path;
  std::string shard;  // "K/N"
  bool no_report = false;
  int fusion_cache_mb = static_cast<int>(dense::kDefaultFusionCacheBytes / (1024 * 1024));
  // Whether --min_num_consistent was given: the default adapts to references
  // with fewer sources, a value the user chose does not
  // (dense::PlanMinConsistentViews).
  bool min_num_consistent_given = false;
  std::string command_line;  // shown in the report

  void Check() const;
  // What the geometric pass is asked: `geometric`'s thresholds and support
  // with `filter`'s sources and confidence.
  fusion::GeometricFilterOptions GeometricRule() const {
    fusion::GeometricFilterOptions rule = filter;
    rule.max_reprojection_error = geometric.max_reprojection_error;
    rule.max_relative_depth_error = geometric.max_relative_depth_error;
    rule.min_support = geometric.min_support;
    rule.support_radius = geometric.support_radius;
    return rule;
  }
  // What fusion is asked: `fusion` with the consistency rule `filter`.
  fusion::FusionOptions FusionRequest() const {
    fusion::FusionOptions request = fusion;
    request.consistency = filter;
    return request;
  }
};

// "K/N" with 0 <= K < N.
std::pair<int, int> ParseShard(const std::string& text) {
  int index = -1, count = -1;
  char slash = 0, extra = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &index, &slash, &count, &extra) != 3 || slash != '/' ||
      count < 1 || index < 0 || index >= count) {
    throw std::invalid_argument("--shard must be K/N with 0 <= K < N (e.g. 0/4), got '" + text +
                                "'");
  }
  return {index, count};
}

void Options::Check() const {
  if (workspace_path.empty()) throw std::invalid_argument("--workspace_path must not be empty");
  const std::vector<std::string> modes = {"full", "photometric", "fuse", "export", "plan"};
  if (std::find(modes.begin(), modes.end(), mode) == modes.end()) {
    throw std::invalid_argument("--mode must be full, photometric, fuse, export or plan, got '" +
                                mode + "'");
  }
  plan.Check();
  if (mode == "full" || mode == "photometric") photometric.Check();
  // The filter's own Check() names its fields; these name the options.
  if (!(filter.max_reprojection_error > 0) || !std::isfinite(filter.max_reprojection_error)) {
    throw std::invalid_argument("--max_reproj_error must be a positive number of pixels");
  }
  if (!(filter.max_relative_depth_error > 0) || !std::isfinite(filter.max_relative_depth_error)) {
    throw std::invalid_argument("--max_depth_error must be a positive fraction");
  }
  if (filter.min_consistent_views < 0) {
    throw std::invalid_argument("--min_num_consistent must be >= 0");
  }
  if (!(filter.min_confidence >= 0 && filter.min_confidence <= 1)) {
    throw std::invalid_argument("--min_confidence must be in [0, 1]");
  }
  if (!(geometric.max_reprojection_error > 0) || !std::isfinite(geometric.max_reprojection_error)) {
    throw std::invalid_argument("--filter_max_reproj_error must be a positive number of pixels");
  }
  if (!(geometric.max_relative_depth_error > 0) || !std::isfinite(geometric.max_relative_depth_error)) {
    throw std::invalid_argument("--filter_max_depth_error must be a positive fraction");
  }
  if (!(geometric.min_support >= 0 && geometric.min_support <= 1)) {
    throw std::invalid_argument("--filter_min_support must be in [0, 1]");
  }
  if (geometric.support_radius < 1 || geometric.support_radius > fusion::kMaxSupportRadius) {
    throw std::invalid_argument("--filter_support_radius must be in [1, " +
                                std::to_string(fusion::kMaxSupportRadius) + "]");
  }
  filter.Check();
  GeometricRule().Check();
  if (!(fusion.max_normal_error >= 0 && fusion.max_normal_error <= 180)) {
    throw std::invalid_argument("--max_normal_error must be in [0, 180] degrees");
  }
  if (fusion.max_num_pixels < 1) throw std::invalid_argument("--max_num_pixels must be at least 1");
  if (fusion.max_num_pixels < filter.min_consistent_views + 1) {
    throw std::invalid_argument("--max_num_pixels (" + std::to_string(fusion.max_num_pixels) +
                                ") must be at least --min_num_consistent + 1 (" +
                                std::to_string(filter.min_consistent_views + 1) +
                                "): a point holds the reference pixel and the pixels it must agree with");
  }
  if (fusion.max_traversal_depth < 1) throw std::invalid_argument("--max_traversal_depth must be at least 1");
  if (fusion.check_num_images < 1) throw std::invalid_argument("--check_num_images must be at least 1");
  FusionRequest().Check();
  if (fusion_cache_mb < 1) throw std::invalid_argument("--fusion_cache_mb must be at least 1");
  if (mode == "export" && export_path.empty()) {
    throw std::invalid_argument("--mode export needs --export_path");
  }
  if (!shard.empty()) ParseShard(shard);
  if ((!shard.empty() || !image_list_path.empty()) && mode != "photometric" && mode != "plan") {
    throw std::invalid_argument(
        "--shard and --image_list split the photometric pass: use them with --mode photometric, "
        "then run --mode fuse once every part is done");
  }
}

// Takes COLMAP's spelling `colmap` of our option `ours` into `target` when it
// was given; both given with different values is an error.
template <typename T>
void TakeColmapSpelling(const po::variables_map& values, const std::string& ours,
                        const std::string& colmap, T* target) {
  if (values.count(colmap) == 0) return;
  const T theirs = values[colmap].as<T>();
  if (values.count(ours) > 0 && !values[ours].defaulted() && values[ours].as<T>() != theirs) {
    throw std::invalid_argument("--" + ours + " and --" + colmap +
                                " are the same option with different values: give one");
  }
  *target = theirs;
}

std::optional<Options> ParseCommandLine(int argc, char** argv) {
  Options o;
  po::options_description description(kDescription);
  // clang-format off
  description.add_options()
      ("help,h", "Print this help and exit.")
      ("workspace_path", po::value<std::string>(&o.workspace_path),
       "COLMAP dense workspace (required): the output folder of image_undistorter.")
      ("mode", po::value<std::string>(&o.mode)->default_value(o.mode),
       "full, photometric, fuse, export or plan (see above).")
      ("model_path", po::value<std::string>(&o.photometric.estimator.model_path),
       "Network weights (.safetensors written by dispmvs_train). Default: the shipped "
       "model v2 weights, found beside the program (BIN/../share/dispmvs/models/"
       "dispmvs_small.safetensors, where `cmake --install` puts them), else in the source "
       "tree it was built from (models/).")
      ("max_image_size", po::value<int>(&o.photometric.max_image_size)->default_value(-1),
       "Downscale images whose larger side exceeds this (maps are written at that "
       "size, as PatchMatch does); -1 = full size.")
      ("max_num_src_images", po::value<int>(&o.plan.max_num_src_images)
           ->default_value(o.plan.max_num_src_images),
       "Most source views per reference for `__auto__` selection (DispMVS was trained "
       "with 4). `__all__` and explicit lists in patch-match.cfg are used as written.")
      ("min_triangulation_angle", po::value<double>(&o.plan.min_triangulation_angle)
           ->default_value(o.plan.min_triangulation_angle, "1"),
       "Degrees; `__auto__` ignores sources whose triangulation angle with the reference "
       "(75th percentile over shared points, or over frustum samples when chosen from "
       "the poses) is smaller.")
      ("depth_min", po::value<double>(&o.plan.depth_min)->default_value(-1),
       "Depth-range hint for every image (with --depth_max) instead of the sparse points'. "
       "Needed by the paper's weights (init = random) on a workspace without sparse points; "
       "optional with model v2 weights (init = match).")
      ("depth_max", po::value<double>(&o.plan.depth_max)->default_value(-1),
       "See --depth_min.")
      ("depth_range_widening", po::value<double>(&o.plan.depth_range_widening)
           ->default_value(1),
       "x >= 1: use [d_min / x, d_max * x] instead of every image's hint (a robustness test: "
       "the network should not care; see bench/depth_range_robustness.sh).")
      ("depth_min_percentile", po::value<double>(&o.plan.depth_min_percentile)
           ->default_value(o.plan.depth_min_percentile, "0.01"),
       "Percentile (fraction) of an image's sparse depths taken as the low end of its hint.")
      ("depth_max_percentile", po::value<double>(&o.plan.depth_max_percentile)
           ->default_value(o.plan.depth_max_percentile, "0.99"),
       "Percentile taken as the high end.")
      ("depth_stretch_ratio", po::value<double>(&o.plan.depth_stretch_ratio)
           ->default_value(o.plan.depth_stretch_ratio, "0.25"),
       "In [0, 1): the hint is [(1 - s) * low, (1 + s) * high].")
      ("depth_min_num_points", po::value<int>(&o.plan.depth_min_num_points)
           ->default_value(o.plan.depth_min_num_points),
       "Images seeing fewer sparse points use the union of the others' ranges.")
      ("coarse_iterations", po::value<int>(&o.photometric.estimator.coarse_iterations)
           ->default_value(0),
       "GRU iterations at 1/16 resolution; 0 = the weights file's.")
      ("fine_iterations", po::value<int>(&o.photometric.estimator.fine_iterations)
           ->default_value(0),
       "GRU iterations at 1/4 resolution; 0 = the weights file's (2). 3 is more accurate "
       "and 1 a third faster than 2 (models/README.md, \"GRU iterations\").")
      ("feature_cache_mb", po::value<int>(&o.photometric.estimator.feature_cache_mb)
           ->default_value(o.photometric.estimator.feature_cache_mb),
       "MiB of encoder features kept across reference views, so an image that is a "
       "source of several references is encoded once (about 4 MiB per image at 640x512, "
       "25 MiB at 1600x1152); 0 = encode every view of every reference.")
      ("tensor_cache_mb", po::value<int>(&o.photometric.estimator.tensor_cache_mb)
           ->default_value(o.photometric.estimator.tensor_cache_mb),
       "On the CPU: MiB of freed network maps of 32 MiB and more kept for reuse (from "
       "about 2 megapixels the maps are that large); 0 = none kept, each mapped afresh by "
       "the C library, several times slower at 3 megapixels and more.")
      ("band_megapixels", po::value<double>(&o.photometric.estimator.band_megapixels)
           ->default_value(o.photometric.estimator.band_megapixels),
       "The network's fine stage runs in bands of rows of about this many megapixels "
       "(with 108 rows of overlap on either side), so its memory stops growing with the "
       "image: less memory, a little more time; 0 = the whole image at once. The maps "
       "agree with a whole-image pass to float rounding.")
      ("device", po::value<std::string>(&o.photometric.estimator.device)
           ->default_value(o.photometric.estimator.device),
       "cpu, cuda or cuda:<gpu index> (needs a CUDA build of LibTorch).")
      ("precision", po::value<std::string>(&o.photometric.estimator.precision)
           ->default_value(o.photometric.estimator.precision),
       "Arithmetic of the network's GRU update convolutions: auto (bf16 on a CPU with "
       "native bf16 instructions, AVX-512 BF16 or AMX, else fp32), fp32 or bf16. bf16 is "
       "about a sixth faster per view with the same accuracy (docs/benchmarks.md).")
      ("refinement", po::value<std::string>(&o.photometric.estimator.refinement)
           ->default_value(o.photometric.estimator.refinement),
       "After the network: ncc (a search of +-refine_steps hypotheses along each source's "
       "epipolar line around the network's depth, scored by normalised cross-correlation "
       "of the images; docs/dense.md) or none (the network's depth as it is).")
      ("refine_window_radius",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.window_radius)
           ->default_value(o.photometric.estimator.refinement_options.window_radius),
       "--refinement ncc: the correlation window is (2r+1) x (2r+1) pixels.")
      ("refine_window_shift",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.window_shift)
           ->default_value(o.photometric.estimator.refinement_options.window_shift),
       "--refinement ncc: score every depth at a pixel by the best of five correlation windows "
       "that contain it, centred and shifted this many pixels left, right, up and down (at most "
       "--refine_window_radius): a shifted window can lie on the pixel's own surface where the "
       "centred one straddles a depth edge. 0 = the centred window alone.")
      ("refine_steps", po::value<int64_t>(&o.photometric.estimator.refinement_options.steps)
           ->default_value(o.photometric.estimator.refinement_options.steps),
       "--refinement ncc: the full-resolution search's hypotheses on each side of its start "
       "(the network's depth, or the coarse propagation's where that correlates better); "
       "6 gives the old search alone with --refine_propagation_rounds 0.")
      ("refine_step_pixels",
       po::value<double>(&o.photometric.estimator.refinement_options.step_pixels)
           ->default_value(o.photometric.estimator.refinement_options.step_pixels,
                           FormatDefault(o.photometric.estimator.refinement_options.step_pixels)),
       "--refinement ncc: their spacing along the epipolar line of the source where the "
       "match moves most, pixels.")
      ("refine_min_ncc", po::value<double>(&o.photometric.estimator.refinement_options.min_ncc)
           ->default_value(o.photometric.estimator.refinement_options.min_ncc,
                           FormatDefault(o.photometric.estimator.refinement_options.min_ncc)),
       "--refinement ncc: the correlation needed to replace the network's depth.")
      ("refine_min_texture",
       po::value<double>(&o.photometric.estimator.refinement_options.min_texture)
           ->default_value(o.photometric.estimator.refinement_options.min_texture,
                           FormatDefault(o.photometric.estimator.refinement_options.min_texture)),
       "--refinement ncc: the reference window's grey-value standard deviation needed "
       "(grey values in [0, 1]).")
      ("refine_propagation_rounds",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.propagation_rounds)
           ->default_value(o.photometric.estimator.refinement_options.propagation_rounds),
       "--refinement ncc: rounds of propagation (at --refine_propagation_scale), 0 = none: every pixel "
       "tries the planes of the pixels refine_propagation_distance, half that, ... "
       "(refine_propagation_levels jumps) away in four directions and keeps the one that "
       "correlates best, so that right depth spreads over the network's wrong blocks.")
      ("refine_propagation_distance",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.propagation_distance)
           ->default_value(o.photometric.estimator.refinement_options.propagation_distance),
       "--refinement ncc: the propagation's longest jump, pixels.")
      ("refine_propagation_levels",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.propagation_levels)
           ->default_value(o.photometric.estimator.refinement_options.propagation_levels),
       "--refinement ncc: jumps per propagation round, each half the one before.")
      ("refine_propagation_slope_radius",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.propagation_slope_radius)
           ->default_value(o.photometric.estimator.refinement_options.propagation_slope_radius),
       "--refinement ncc: a propagated plane's slope is fitted to the depth over "
       "(2r+1) x (2r+1) pixels.")
      ("refine_propagation_scale",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.propagation_scale)
           ->default_value(o.photometric.estimator.refinement_options.propagation_scale),
       "--refinement ncc: 1 = propagation at full resolution after the search; 2 or 4 = "
       "search and propagation first on images averaged over 2x2 or 4x4 blocks (distances "
       "scaled), then the full-resolution search from that surface wherever it correlates "
       "better there than the network's: most of propagation's gain at a fraction of its time.")
      ("refine_full_resolution_rounds",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.full_resolution_rounds)
           ->default_value(o.photometric.estimator.refinement_options.full_resolution_rounds),
       "--refinement ncc with --refine_propagation_scale 2 or 4: rounds of propagation at full "
       "resolution after the full-resolution search, with jumps of refine_propagation_distance / "
       "scale pixels and less: each surface found at the coarse scale gets its full-resolution "
       "plane.")
      ("refine_full_resolution_levels",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.full_resolution_levels)
           ->default_value(o.photometric.estimator.refinement_options.full_resolution_levels),
       "--refinement ncc: jumps per full-resolution round, each half the one before.")
      ("refine_sweep_hypotheses",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.sweep_hypotheses)
           ->default_value(o.photometric.estimator.refinement_options.sweep_hypotheses),
       "--refinement ncc: at most this many constant depths tried at every pixel over the "
       "network's depth range, in the source chosen most, before the search (on the coarse grid "
       "with --refine_propagation_scale 2 or 4); their smoothed winner becomes the start where it "
       "correlates better than the network's depth: the surfaces the network missed. 0 = off.")
      ("refine_sweep_step_pixels",
       po::value<double>(&o.photometric.estimator.refinement_options.sweep_step_pixels)
           ->default_value(o.photometric.estimator.refinement_options.sweep_step_pixels),
       "--refinement ncc: the sweep's spacing, pixels of that grid at the median pixel (fewer "
       "hypotheses where refine_sweep_hypotheses would space them closer).")
      ("refine_unseen_slope_radius",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.unseen_slope_radius)
           ->default_value(o.photometric.estimator.refinement_options.unseen_slope_radius),
       "--refinement ncc: where no source sees a pixel at its refined depth (its match outside "
       "every source image), extend the plane of the nearest pixel a source sees, its slopes "
       "fitted over (2R+1)^2 such pixels; 0 = off (the network's depth stays there).")
      ("refine_trusted_plane_ncc",
       po::value<double>(&o.photometric.estimator.refinement_options.trusted_plane_min_ncc)
           ->default_value(o.photometric.estimator.refinement_options.trusted_plane_min_ncc,
                           FormatDefault(o.photometric.estimator.refinement_options.trusted_plane_min_ncc)),
       "--refinement ncc: after propagation, every pixel also tries the plane of the nearest "
       "refined pixel whose windows correlate at least this well (NCC), however far, and keeps it "
       "where it correlates better: repairs wrong blocks wider than propagation's jumps. 0 = off.")
      ("refine_trusted_plane_axis_anchors",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.trusted_plane_axis_anchors)
           ->default_value(o.photometric.estimator.refinement_options.trusted_plane_axis_anchors),
       "--refinement ncc, with long-range planes: also try the planes of the nearest such pixels "
       "along the pixel's row (2) and its row and column (4), on a wrong block's other sides; "
       "0 = the nearest alone.")
      ("refine_local_plane_radius",
       po::value<int64_t>(&o.photometric.estimator.refinement_options.local_plane_radius)
           ->default_value(o.photometric.estimator.refinement_options.local_plane_radius),
       "--refinement ncc: last, every pixel takes the value of the least-squares plane through "
       "the well-correlated pixels of the (2R+1)^2 window around it, where that lies near its own "
       "depth (--refine_local_plane_max_change): averages out the per-pixel matches' scatter. "
       "0 = off.")
      ("refine_local_plane_max_change",
       po::value<double>(&o.photometric.estimator.refinement_options.local_plane_max_change)
           ->default_value(o.photometric.estimator.refinement_options.local_plane_max_change,
                           FormatDefault(o.photometric.estimator.refinement_options.local_plane_max_change)),
       "--refinement ncc, with local planes: the largest relative change of inverse depth they "
       "make, in (0, 1]; keeps them off depth edges.")
      ("confidence", po::value<std::string>(&o.photometric.estimator.confidence)
           ->default_value(o.photometric.estimator.confidence),
       "The confidence maps: model (the probability that a pixel's depth is within 2 %, "
       "from the network's confidence and the refinement's correlation and texture, by the "
       "confidence model the weights carry; where they carry none, or with --refinement none, "
       "the network's) or network (the network's own: how peaked its last match was).")
      ("fill_below_confidence",
       po::value<double>(&o.photometric.estimator.fill_options.below)
           ->default_value(o.photometric.estimator.fill_options.below,
                           FormatDefault(o.photometric.estimator.fill_options.below)),
       "With --confidence model: pixels whose confidence is below this take the plane of the "
       "nearest pixel with at least --fill_anchor_confidence, extended over them (their "
       "confidence stays low). A prior of large planes, for buildings and rooms (0.5: real "
       "photographs' pixels within 2 % 0.626 against 0.585; scenes of small separate objects "
       "lose); 0 = off, the refined depth everywhere.")
      ("fill_anchor_confidence",
       po::value<double>(&o.photometric.estimator.fill_options.anchor)
           ->default_value(o.photometric.estimator.fill_options.anchor,
                           FormatDefault(o.photometric.estimator.fill_options.anchor)),
       "The confidence a pixel needs to lend its plane to --fill_below_confidence's pixels.")
      ("fill_slope_radius",
       po::value<int64_t>(&o.photometric.estimator.fill_options.slope_radius)
           ->default_value(o.photometric.estimator.fill_options.slope_radius),
       "The fill's planes: slopes fitted over (2R+1)^2 confident pixels.")
      ("fill_max_change",
       po::value<double>(&o.photometric.estimator.fill_options.max_change)
           ->default_value(o.photometric.estimator.fill_options.max_change,
                           FormatDefault(o.photometric.estimator.fill_options.max_change)),
       "The fill replaces a depth only where the plane's inverse depth differs from it by at "
       "most this, relative (it snaps roughly right depths onto the confident surface, and does "
       "not move pixels onto another one); 0 = any change.")
      ("threads", po::value<int>(&o.photometric.estimator.threads)->default_value(0),
       "CPU threads for the network; 0 = one per core.")
      ("seed", po::value<uint64_t>(&o.photometric.seed)->default_value(0),
       "Seed of the random initialisation (per image, so results do not depend on order "
       "or sharding).")
      ("image_list", po::value<std::string>(&o.image_list_path),
       "File with one reference image name per line: only those (--mode photometric).")
      ("shard", po::value<std::string>(&o.shard),
       "K/N: only every N-th reference starting at K (--mode photometric), e.g. "
       "--shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT.")
      ("overwrite", po::bool_switch(&o.photometric.overwrite),
       "Recompute photometric maps that already exist.")
      ("max_reproj_error", po::value<double>(&o.filter.max_reprojection_error)
           ->default_value(o.filter.max_reprojection_error,
                          FormatDefault(o.filter.max_reprojection_error)),
       "Fusion: largest forward-backward reprojection error, pixels, of a source pixel fused "
       "with a reference pixel.")
      ("max_depth_error", po::value<double>(&o.filter.max_relative_depth_error)
           ->default_value(o.filter.max_relative_depth_error,
                          FormatDefault(o.filter.max_relative_depth_error)),
       "Fusion: largest relative depth difference between a pixel and its reprojection.")
      ("filter_max_reproj_error", po::value<double>(&o.geometric.max_reprojection_error)
           ->default_value(o.geometric.max_reprojection_error,
                          FormatDefault(o.geometric.max_reprojection_error)),
       "Geometric filter: largest forward-backward reprojection error, pixels (looser than "
       "fusion's: the support rule below keeps its precision).")
      ("filter_max_depth_error", po::value<double>(&o.geometric.max_relative_depth_error)
           ->default_value(o.geometric.max_relative_depth_error,
                          FormatDefault(o.geometric.max_relative_depth_error)),
       "Geometric filter: largest relative depth difference.")
      ("min_num_consistent", po::value<int>(&o.filter.min_consistent_views)
           ->default_value(o.filter.min_consistent_views),
       "Source views that must agree for a pixel to be kept (geometric filter and fusion). "
       "Left at the default, a reference with fewer sources that have depth maps (a stereo "
       "pair: 1 each) needs what it has, at least 1, with a warning; a value given here that "
       "no reference can meet stops the run before any work.")
      ("min_confidence", po::value<double>(&o.filter.min_confidence)->default_value(0.1, "0.1"),
       "Geometric filter and fusion: drop pixels (reference and source) whose confidence is "
       "lower. With the default --confidence model it is the estimated probability that the "
       "depth is within 2 %, and 0 where no image signal lies within 32 pixels: 0.1 drops what the "
       "images give no evidence for (all-black or all-white views fuse nothing) and little "
       "else. 0 keeps every pixel, as before.")
      ("filter_min_support", po::value<double>(&o.geometric.min_support)
           ->default_value(o.geometric.min_support, FormatDefault(o.geometric.min_support)),
       "Geometric filter: a pixel whose sources agree is kept only where at least this share "
       "of the pixels of the window around it (--filter_support_radius) agree too: a wrong "
       "depth agrees with a source by accident at scattered pixels, a right one over patches "
       "of a surface. 0 = off, COLMAP's rule (the filter before: --filter_min_support 0 "
       "--filter_max_reproj_error 1 --filter_max_depth_error 0.01).")
      ("filter_support_radius", po::value<int>(&o.geometric.support_radius)
           ->default_value(o.geometric.support_radius),
       "Geometric filter: the support window is (2 r + 1) x (2 r + 1) pixels.")
      ("mask_path", po::value<std::string>(&o.mask_path),
       "Folder of masks, COLMAP's: MASK/NAME.png for image NAME (or MASK/NAME when NAME ends "
       "in .png), resampled to the maps' size; black pixels (red channel 0) are ignored by the "
       "geometric pass and fusion: no point comes from them and they agree with nothing. An "
       "image without a mask file is used whole.")
      ("bbox_path", po::value<std::string>(&o.bbox_path),
       "Bounding-box file, COLMAP's: six numbers, min x y z then max x y z (world "
       "coordinates); pixels whose 3-D point lies outside are not fused.")
      ("max_normal_error", po::value<double>(&o.fusion.max_normal_error)->default_value(180),
       "Fusion: degrees between the normals of a reference pixel and an agreeing source pixel "
       "beyond which the source is not fused with it (COLMAP's test); 180 = no test. Off by "
       "default: our normals come from the depth maps' differences, and COLMAP's 10 kept 12 % "
       "of the example's points (F-score 82 -> 63 %) at the same precision "
       "(docs/colmap-options.md).")
      ("max_num_pixels", po::value<int>(&o.fusion.max_num_pixels)->default_value(10000),
       "Fusion: most pixels averaged into one point (the reference's, then its agreeing "
       "sources in order); the others stay free for later points.")
      ("max_traversal_depth", po::value<int>(&o.fusion.max_traversal_depth)->default_value(100),
       "Fusion, COLMAP's traversal depth: 1 = each point is its reference pixel alone "
       "(agreement still required); 2 or more = the reference pixel and its agreeing sources' "
       "pixels, which is as far as this fusion goes.")
      ("check_num_images", po::value<int>(&o.fusion.check_num_images)->default_value(50),
       "Fusion: each reference is checked against at most its first N sources (the most "
       "overlapping first).")
      ("fusion_cache_mb", po::value<int>(&o.fusion_cache_mb)->default_value(o.fusion_cache_mb),
       "Fusion reads each image's maps when it needs them and keeps at most this many MB "
       "of them (more only if one reference and its sources need it), so memory does not "
       "grow with the number of images.")
      ("no_report", po::bool_switch(&o.no_report),
       "Do not write WS/dispmvs_report.html, the run report (depth, normal and confidence "
       "pictures per view beside PatchMatch's, coverage, the fused cloud; dispmvs_report "
       "writes it for any workspace).")
      ("output_path", po::value<std::string>(&o.output_path),
       "Fused point cloud; default WS/fused.ply (its visibility goes to OUTPUT.vis).")
      ("export_path", po::value<std::string>(&o.export_path),
       "Target workspace of --mode export.");
  // clang-format on

  // COLMAP's spellings of the same settings, so that a `colmap
  // patch_match_stereo` / `stereo_fusion` command line carries over.
  po::options_description colmap_spellings(
      "COLMAP's spellings, accepted for the options above (giving both spellings with "
      "different values is an error)");
  // clang-format off
  colmap_spellings.add_options()
      ("StereoFusion.mask_path", po::value<std::string>(), "= --mask_path")
      ("StereoFusion.max_reproj_error", po::value<double>(), "= --max_reproj_error")
      ("StereoFusion.max_depth_error", po::value<double>(), "= --max_depth_error")
      ("StereoFusion.max_normal_error", po::value<double>(), "= --max_normal_error")
      ("StereoFusion.min_num_pixels", po::value<int>(),
       "N = --min_num_consistent N-1 (a point's pixels: the reference's and N-1 agreeing)")
      ("StereoFusion.max_num_pixels", po::value<int>(), "= --max_num_pixels")
      ("StereoFusion.max_traversal_depth", po::value<int>(), "= --max_traversal_depth")
      ("StereoFusion.check_num_images", po::value<int>(), "= --check_num_images")
      ("StereoFusion.max_image_size", po::value<int>(),
       "= --max_image_size (the maps are computed at that size, so fusion runs at it)")
      ("PatchMatchStereo.max_image_size", po::value<int>(), "= --max_image_size")
      ("PatchMatchStereo.depth_min", po::value<double>(), "= --depth_min")
      ("PatchMatchStereo.depth_max", po::value<double>(), "= --depth_max")
      ("PatchMatchStereo.min_triangulation_angle", po::value<double>(), "= --min_triangulation_angle")
      ("PatchMatchStereo.filter_min_num_consistent", po::value<int>(), "= --min_num_consistent")
      ("PatchMatchStereo.filter_geom_consistency_max_cost", po::value<double>(),
       "= --filter_max_reproj_error")
      ("workspace_format", po::value<std::string>(), "COLMAP only (PMVS workspaces are not read)");
  // clang-format on
  description.add(colmap_spellings);

  po::variables_map values;
  if (!cli::ParseCommandLine(argc, argv, description, &values)) return std::nullopt;
  TakeColmapSpelling(values, "mask_path", "StereoFusion.mask_path", &o.mask_path);
  TakeColmapSpelling(values, "max_reproj_error", "StereoFusion.max_reproj_error",
                     &o.filter.max_reprojection_error);
  TakeColmapSpelling(values, "max_depth_error", "StereoFusion.max_depth_error",
                     &o.filter.max_relative_depth_error);
  TakeColmapSpelling(values, "max_normal_error", "StereoFusion.max_normal_error",
                     &o.fusion.max_normal_error);
  TakeColmapSpelling(values, "max_num_pixels", "StereoFusion.max_num_pixels", &o.fusion.max_num_pixels);
  TakeColmapSpelling(values, "max_traversal_depth", "StereoFusion.max_traversal_depth",
                     &o.fusion.max_traversal_depth);
  TakeColmapSpelling(values, "check_num_images", "StereoFusion.check_num_images",
                     &o.fusion.check_num_images);
  TakeColmapSpelling(values, "max_image_size", "StereoFusion.max_image_size",
                     &o.photometric.max_image_size);
  TakeColmapSpelling(values, "max_image_size", "PatchMatchStereo.max_image_size",
                     &o.photometric.max_image_size);
  TakeColmapSpelling(values, "depth_min", "PatchMatchStereo.depth_min", &o.plan.depth_min);
  TakeColmapSpelling(values, "depth_max", "PatchMatchStereo.depth_max", &o.plan.depth_max);
  TakeColmapSpelling(values, "min_triangulation_angle", "PatchMatchStereo.min_triangulation_angle",
                     &o.plan.min_triangulation_angle);
  TakeColmapSpelling(values, "min_num_consistent", "PatchMatchStereo.filter_min_num_consistent",
                     &o.filter.min_consistent_views);
  TakeColmapSpelling(values, "filter_max_reproj_error",
                     "PatchMatchStereo.filter_geom_consistency_max_cost",
                     &o.geometric.max_reprojection_error);
  if (values.count("StereoFusion.max_image_size") && values.count("PatchMatchStereo.max_image_size") &&
      values["StereoFusion.max_image_size"].as<int>() != values["PatchMatchStereo.max_image_size"].as<int>()) {
    throw std::invalid_argument(
        "--StereoFusion.max_image_size and --PatchMatchStereo.max_image_size differ: dispmvs fuses "
        "its maps at the size it computes them, give one size");
  }
  // Read now, so that a bad file stops the run before the network runs.
  if (!o.bbox_path.empty()) o.fusion.bounding_box = fusion::ReadBoundingBox(o.bbox_path);
  o.min_num_consistent_given = !values["min_num_consistent"].defaulted() ||
                               values.count("PatchMatchStereo.filter_min_num_consistent") > 0;
  if (values.count("StereoFusion.min_num_pixels")) {
    const int pixels = values["StereoFusion.min_num_pixels"].as<int>();
    if (pixels < 1) throw std::invalid_argument("--StereoFusion.min_num_pixels must be at least 1");
    if (o.min_num_consistent_given && o.filter.min_consistent_views != pixels - 1) {
      throw std::invalid_argument("--StereoFusion.min_num_pixels " + std::to_string(pixels) +
                                  " means --min_num_consistent " + std::to_string(pixels - 1) +
                                  ", but --min_num_consistent " +
                                  std::to_string(o.filter.min_consistent_views) + " was given too");
    }
    o.filter.min_consistent_views = pixels - 1;
    o.min_num_consistent_given = true;
  }
  if (values.count("workspace_format")) {
    std::string format = values["workspace_format"].as<std::string>();
    std::transform(format.begin(), format.end(), format.begin(), [](unsigned char c) { return std::tolower(c); });
    if (format != "colmap") {
      throw std::invalid_argument("--workspace_format: only COLMAP workspaces are read, got '" +
                                  values["workspace_format"].as<std::string>() + "'");
    }
  }
  for (int i = 0; i < argc; ++i) o.command_line += (i > 0 ? " " : "") + std::string(argv[i]);
  if (values.count("workspace_path") == 0) {
    throw std::invalid_argument("--workspace_path is required (see --help)");
  }
  if (o.photometric.estimator.model_path.empty() &&
      (o.mode == "full" || o.mode == "photometric")) {
    o.photometric.estimator.model_path = cli::FindShippedModel().string();
  }
  o.Check();
  return o;
}

std::vector<std::string> ReadImageList(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw colmap_io::IoError(path, "cannot open the image list");
  std::vector<std::string> names;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!line.empty() && line[0] != '#') names.push_back(line);
  }
  if (names.empty()) throw colmap_io::IoError(path, "the image list names no image");
  return names;
}

void PrintPassSummary(const char* pass, const dense::PassSummary& summary, std::ostream& out) {
  out << "summary: " << pass << ": " << summary.done << " done, " << summary.skipped_existing
      << " skipped (existing), " << summary.skipped_no_sources << " skipped (no sources or input), ";
  if (summary.skipped_claimed > 0) {
    out << summary.skipped_claimed << " skipped (another process was computing them), ";
  }
  out << summary.failures.size() << " failed";
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, ", %.1f s\n", summary.seconds);
  out << seconds;
  for (const std::string& failure : summary.failures) out << "  failed: " << failure << '\n';
}

// The process's peak resident memory so far (what /usr/bin/time reports).
double PeakMemoryMegabytes() {
  rusage usage{};
  if (::getrusage(RUSAGE_SELF, &usage) != 0) return 0;
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // kilobytes on Linux
}

// Why fusion may have produced nothing, from what the run knows.
void PrintEmptyCloudWarning(const Options& options, const dense::DensePlan& plan,
                            const dense::FusionSummary& fusion, const fs::path& ply) {
  std::cout << "warning: " << ply.string() << " has 0 points: ";
  if (fusion.num_images == 0) {
    std::cout << "no image has a photometric depth map to fuse (see the photometric lines above)\n";
    return;
  }
  if (fusion.pixels > 0 && fusion.masked_pixels == fusion.pixels) {
    std::cout << "the masks in " << options.mask_path << " (--mask_path) ignore every pixel of the "
              << fusion.num_images << " image(s) with depth maps (black masks: nothing is fused)\n";
    return;
  }
  if (options.fusion.bounding_box) {
    std::cout << "(the bounding box of " << options.bbox_path << " leaves out every pixel outside it) ";
  }
  std::cout << "no pixel of the " << fusion.num_images
            << " image(s) with depth maps agreed with enough of its sources (--min_num_consistent "
            << options.filter.min_consistent_views;
  if (!plan.min_consistent_views.empty()) {
    std::cout << ", lowered for " << plan.min_consistent_views.size()
              << " reference image(s) as warned above";
  }
  std::cout << "; agreeing = within --max_reproj_error and --max_depth_error";
  if (options.filter.min_confidence > 0) std::cout << ", at --min_confidence or more";
  std::cout << "); the geometric lines above show the share each image kept\n";
}

int Run(const Options& options) {
  const auto start = std::chrono::steady_clock::now();
  std::optional<dense::DepthEstimator::WeightsInfo> weights;
  if (options.mode == "full" || options.mode == "photometric") {
    weights = dense::DepthEstimator::CheckWeightsFile(options.photometric.estimator.model_path);
  }
  const colmap_io::Workspace workspace(options.workspace_path);
  dense::DensePlan plan = dense::PlanDenseReconstruction(workspace, options.plan);
  if (!options.image_list_path.empty()) {
    dense::RestrictToImages(ReadImageList(options.image_list_path), &plan);
  }
  if (!options.shard.empty()) {
    const auto [index, count] = ParseShard(options.shard);
    dense::RestrictToShard(index, count, &plan);
  }
  if (options.mode == "plan") {
    dense::PrintPlan(plan, std::cout);
    return 0;
  }
  if (options.mode == "export") {
    dense::ExportForColmap(workspace, plan, options.export_path, std::cout);
    return 0;
  }
  // Weights that need a hint and images without one: stop before anything
  // is printed or written.
  if (weights) {
    dense::CheckHintsForWeights(plan, dense::ReferencesWithoutHint(plan),
                                weights->needs_depth_range);
  }
  // Likewise a --min_num_consistent that the sources cannot meet (a stereo
  // pair has one source map per view): said now, not as an empty fused.ply
  // after the network has run.
  const bool runs_fusion = options.mode == "full" || options.mode == "fuse";
  std::string consistency_warning;
  if (runs_fusion) {
    consistency_warning = dense::PlanMinConsistentViews(
        options.filter.min_consistent_views, options.min_num_consistent_given, &plan);
  }
  std::cout << "plan: " << plan.problems.size() << " reference image(s) from "
            << plan.problems_source << '\n';
  const std::string note = dense::WithoutSparsePointsNote(plan);
  if (!note.empty()) std::cout << "plan: " << note << '\n';
  for (auto image_id : plan.missing_images) {
    std::cout << "warning: image file missing, not used: " << plan.ImageOf(image_id).name << '\n';
  }
  if (!consistency_warning.empty()) std::cout << "warning: " << consistency_warning << '\n';
  const fs::path ply = options.output_path.empty() ? workspace.root() / "fused.ply"
                                                   : fs::path(options.output_path);
  // A fusion.cfg naming unknown images, or an output that cannot be written,
  // fails now, not after the network has run.
  dense::CheckMapFoldersWritable(workspace);
  if (runs_fusion) {
    dense::FusionImageOrder(workspace, plan);
    colmap_io::AtomicFileWriter probe(ply);  // a temporary file, removed at once
  }
  // Masks: a missing folder stops the run now; images without a mask file
  // are used whole (COLMAP's rule), which is said, since a misnamed folder
  // or file set is the likely cause.
  dense::ImageMasks masks;
  if (runs_fusion && !options.mask_path.empty()) {
    masks = dense::ImageMasks(options.mask_path);
    std::vector<std::string> names;
    for (const auto& [image_id, image] : plan.model.images) names.push_back(image.name);
    const std::size_t with_mask = masks.CountWithMask(names);
    std::cout << "masks: " << with_mask << " of " << names.size() << " image(s) have a mask in "
              << options.mask_path << '\n';
    if (with_mask < names.size()) {
      std::cout << "warning: " << names.size() - with_mask << " image(s) have no mask file (NAME.png) in "
                << options.mask_path << " and are used whole\n";
    }
  }
  bool failed = !plan.missing_images.empty() && options.mode != "fuse";
  std::vector<std::pair<const char*, dense::PassSummary>> summaries;
  if (options.mode == "full" || options.mode == "photometric") {
    summaries.emplace_back("photometric",
                           dense::RunPhotometricPass(workspace, plan, options.photometric, std::cout));
  }
  std::optional<dense::FusionSummary> fusion_summary;
  const fs::path report_path = workspace.root() / "dispmvs_report.html";
  // The geometric maps and the cloud are the workspace's shared outputs: one
  // process at a time writes them (dense/view_claim.h), and it clears what
  // killed runs left beside them.
  std::optional<dense::ViewClaim> fusion_claim;
  long fusion_holder = 0;
  if (runs_fusion) {
    fusion_claim = dense::ClaimGeometricAndFusion(workspace, plan, ply, {report_path}, std::cout,
                                                  &fusion_holder);
  }
  if (fusion_claim) {
    summaries.emplace_back("geometric",
                           dense::RunGeometricPass(workspace, plan, options.GeometricRule(), std::cout, masks));
    fusion_summary = dense::RunFusion(workspace, plan, options.FusionRequest(), ply, std::cout,
                                      static_cast<std::size_t>(options.fusion_cache_mb) << 20, masks);
  }
  for (const auto& [pass, summary] : summaries) {
    PrintPassSummary(pass, summary, std::cout);
    failed = failed || !summary.failures.empty();
    // Not a failure of this run (the other process owns those views), but
    // the user should know this run's part is not all there yet.
    if (summary.skipped_claimed > 0) {
      std::cout << "warning: " << summary.skipped_claimed
                << " view(s) were being computed by another process on this workspace (the same "
                   "--shard started twice?); once it ends, rerun this command to pick up any "
                   "view it did not finish\n";
    }
  }
  if (fusion_summary) {
    std::cout << "summary: fusion: " << fusion_summary->num_points << " points from "
              << fusion_summary->num_images << " image(s)\n";
    // Not a failure (the exit status says whether views failed), but an empty
    // cloud is never what the user wanted: say why it may be.
    if (fusion_summary->num_points == 0) {
      PrintEmptyCloudWarning(options, plan, *fusion_summary, ply);
    }
  }
  if (runs_fusion && !fusion_claim) {
    std::cout << std::flush;  // the error after the summaries, where it is read
    std::cerr << "error: the geometric pass and fusion were not run: another process";
    if (fusion_holder > 0) std::cerr << " (pid " << fusion_holder << ")";
    std::cerr << " is running them on this workspace (its lock: "
              << dense::FusionClaimPath(workspace).string()
              << "); once it ends, rerun with --mode fuse\n";
    failed = true;
  }
  if (fusion_summary && !options.no_report) {
    eval::HtmlReportOptions report;
    report.ply_path = ply.string();
    report.settings = options.command_line;
    // The report only shows what the run wrote: failing to write it (a full
    // disk) is said, but does not fail the run.
    try {
      const eval::HtmlReportSummary written =
          eval::WriteHtmlReport(workspace.root(), report_path, report);
      std::cout << "report: " << report_path.string() << " (" << written.bytes / 1024 << " KB)\n";
    } catch (const std::exception& error) {
      std::cout << "warning: the run report was not written: " << error.what() << '\n';
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  char total[64];
  std::snprintf(total, sizeof total, "summary: total %.1f s, peak memory %.0f MB", seconds,
                PeakMemoryMegabytes());
  std::cout << total << (failed ? " (with failures: exit status 1)" : "") << '\n';
  return failed ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&] {
    const std::optional<Options> options = ParseCommandLine(argc, argv);
    return options ? Run(*options) : 0;
  });
}
