#pragma once
// The plan of a dense reconstruction: the stereo problems (reference image,
// source images) and the depth-range hint of every image, derived once from
// the workspace and used by every pass of dispmvs_colmap.
//
// A workspace need not have sparse points (a model from known poses, or one
// whose points3D were dropped): an image with no hint of its own gets the
// union of the others' (FallbackDepthRange), and when no image has one and
// the user gives none, it has NO hint (HintFor returns nullopt). Model v2
// weights need none; the paper's weights do (CheckHintsForWeights). An
// `__auto__` reference that shares no sparse point with another image gets
// its sources from the camera poses (colmap_io::RankSourceViewsByPose).

#include <cstddef>
#include <map>
#include <optional>
#include <ostream>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "colmap_io/depth_range.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/view_selection.h"
#include "colmap_io/workspace.h"

namespace dispmvs::dense {

struct PlanOptions {
  // DispMVS was trained with N = 5 views, one reference and 4 sources (paper,
  // Sec. 4). More sources cost memory and time linearly and the network never
  // saw them; COLMAP's own `__auto__, 20` is tuned for PatchMatch.
  int max_num_src_images = colmap_io::kDefaultMaxNumSourceImages;
  // COLMAP's PatchMatchStereo.min_triangulation_angle default, degrees.
  double min_triangulation_angle = 1.0;
  // Depth-range hint from the sparse points (colmap_io/depth_range.h; the
  // defaults are COLMAP's).
  double depth_min_percentile = 0.01;
  double depth_max_percentile = 0.99;
  double depth_stretch_ratio = 0.25;
  int depth_min_num_points = 1;
  // A user-given hint for every image instead (both or neither); <= 0 = unset.
  double depth_min = -1;
  double depth_max = -1;
  // Widens every hint (the sparse points' or the user's) to [d_min / x,
  // d_max * x], x >= 1: the depth-range robustness protocol (paper, Table 5;
  // bench/depth_range_robustness.sh). 1 = as derived.
  double depth_range_widening = 1;

  // Throws std::invalid_argument naming the command-line option at fault.
  void Check() const;
  colmap_io::ViewSelectionOptions ViewSelection() const;
  colmap_io::DepthRangeOptions DepthRange() const;
};

struct DensePlan {
  colmap_io::SparseModel model;
  // Where the problems came from: the patch-match.cfg path, or a note that
  // they were generated.
  std::string problems_source;
  std::vector<colmap_io::StereoProblem> problems;
  std::map<colmap_io::image_t, colmap_io::DepthRange> depth_ranges;  // every image
  colmap_io::DepthRange fallback_depth_range;
  std::optional<colmap_io::DepthRange> user_depth_range;  // --depth_min/--depth_max
  double depth_range_widening = 1;  // applied by HintFor
  // Images of the model whose file is missing from WS/images (they are left
  // out of every source list; a reference among them fails alone).
  std::vector<colmap_io::image_t> missing_images;
  // References of `__auto__` entries that share no sparse point with any
  // other image, whose sources were therefore chosen from the camera poses.
  std::set<colmap_io::image_t> pose_selected_references;
  // The depths the pose-based selection sampled when no hint said how far
  // the scene is (colmap_io::GuessSampleDepthsFromPoses); unset otherwise.
  std::optional<std::pair<double, double>> guessed_sample_depths;
  // References whose geometric filter and fusion need fewer agreeing sources
  // than --min_num_consistent, because fewer of their sources have depth maps
  // (set by PlanMinConsistentViews); the others use the option.
  std::map<colmap_io::image_t, int> min_consistent_views;

  // The hint for `image_id`: the user's, else the image's own, else the
  // fallback, widened by depth_range_widening; nullopt when there is none
  // (no sparse points anywhere and no --depth_min/--depth_max).
  // `is_fallback` (optional) says whether the fallback was used.
  std::optional<colmap_io::DepthRange> HintFor(colmap_io::image_t image_id,
                                               bool* is_fallback = nullptr) const;
  // Whether the image's own sparse points gave it a range.
  bool HasOwnDepthRange(colmap_io::image_t image_id) const;
  const colmap_io::Image& ImageOf(colmap_io::image_t image_id) const {
    return model.images.at(image_id);
  }
};

// Reads the model, checks the cameras are undistorted (PINHOLE or
// SIMPLE_PINHOLE: IoError otherwise), resolves the problems from
// stereo/patch-match.cfg or `__auto__` for every image, computes the hints.
// Throws IoError / std::invalid_argument on a workspace that cannot be used
// at all (no registered images among them).
DensePlan PlanDenseReconstruction(const colmap_io::Workspace& workspace,
                                  const PlanOptions& options);

// Keeps the problems whose reference is listed (by name) in `names`; throws
// std::invalid_argument naming a listed image that has no problem.
void RestrictToImages(const std::vector<std::string>& names, DensePlan* plan);
// Keeps problem i when i % count == index (a shard of a batch job).
void RestrictToShard(int index, int count, DensePlan* plan);

// One tab-separated line per problem:
//   NAME d_min= d_max= points= [user|fallback] [poses] sources=...
// d_min=none d_max=none when the image has no hint; "poses" when its sources
// come from the camera poses.
void PrintPlan(const DensePlan& plan, std::ostream& out);

// One line (no newline) saying that the plan was made without sparse points
// for some references (which have no hint of their own, which have none at
// all, whose sources come from the poses), or "" when every reference had
// sparse points. dispmvs_colmap prints it before any pass.
std::string WithoutSparsePointsNote(const DensePlan& plan);

// The references with at least one source and no depth-range hint.
std::vector<colmap_io::image_t> ReferencesWithoutHint(const DensePlan& plan);

// Sources of `problem` that will have a depth map to agree with: those that
// are reference images of the plan with at least one source and an image
// file (the photometric pass computes maps for no other image). The geometric
// filter and fusion can count only these.
int NumSourcesWithMaps(const DensePlan& plan, const colmap_io::StereoProblem& problem);

// Checks --min_num_consistent (`min_consistent_views`, the agreeing sources
// the geometric filter and fusion need) against NumSourcesWithMaps of every
// reference that gets a map, before any work, so that a stereo pair (one
// source each) does not end in an empty cloud without a word:
//   - every reference has enough: returns "";
//   - the value cannot be met by any reference, so the output would certainly
//     be empty: throws std::invalid_argument naming the option and what to
//     pass instead, when `user_set`, or when no reference has any source with
//     a map (then no value but 0 keeps anything);
//   - `user_set`, some references short: returns a warning (one line, no
//     newline) naming them; the value is kept, they keep no pixel;
//   - the default, some references short: sets plan->min_consistent_views to
//     what each has (at least 1) for those and returns a warning naming the
//     option, the default, the value used and how many references.
// Call it on the whole plan (not a shard).
std::string PlanMinConsistentViews(int min_consistent_views, bool user_set, DensePlan* plan);

// Throws std::invalid_argument naming the images, telling the user to pass
// --depth_min and --depth_max or to use model v2 weights, when
// `weights_need_depth_range` and `without_hint` (references without a hint,
// e.g. ReferencesWithoutHint(plan)) is not empty: better before the first
// view than as one failure per view.
void CheckHintsForWeights(const DensePlan& plan,
                          const std::vector<colmap_io::image_t>& without_hint,
                          bool weights_need_depth_range);

}  // namespace dispmvs::dense
