#pragma once
// Source-view selection for a reference image, reproducing COLMAP's
// `__auto__, N` entry of patch-match.cfg (colmap/mvs/model.cc,
// Model::GetMaxOverlappingImages): among the other images, keep those whose
// triangulation angle with the reference reaches a minimum, then take the N
// sharing the most sparse points with it.
//
// Triangulation angle of a pair: for every shared point X, the angle between
// the rays from the two camera centres to X, folded to min(a, pi - a) (as
// COLMAP's CalculateTriangulationAngle does); the pair's angle is the given
// percentile of these (COLMAP: 75th, picked as sorted[round(p/100 * (n-1))]).
// A pair with identical centres therefore has angle 0 and is rejected.
//
// Without sparse points (a model with no points3D, or an image that shares
// none with any other) the same rule runs on VIRTUAL points: a grid of the
// reference's pixels back-projected to a set of depths samples its viewing
// frustum; a candidate's "shared points" are the samples it sees (in front of
// it and inside its image) and its angle is the percentile of their
// triangulation angles. See RankSourceViewsByPose.

#include <cstddef>
#include <map>
#include <optional>
#include <utility>
#include <vector>

#include "colmap_io/depth_range.h"
#include "colmap_io/sparse_model.h"

namespace dispmvs::colmap_io {

struct ViewSelectionOptions {
  // COLMAP's PatchMatchOptions::min_triangulation_angle default, in degrees;
  // pairs whose angle is below it are excluded. In [0, 90].
  double min_triangulation_angle_deg = 1.0;
  // Percentile (in [0, 100]) of the per-point angles used as the pair's angle.
  double triangulation_angle_percentile = 75.0;
  // Pose-based selection only: candidates whose optical axis is turned more
  // than this from the reference's are excluded, in (0, 180]. Beyond about
  // 60 degrees the two views see surfaces so differently that matching along
  // epipolar lines rarely works, however much the frusta overlap.
  double max_viewing_angle_deg = 60.0;

  // Throws std::invalid_argument naming the offending field.
  void Check() const;
};

struct SourceViewCandidate {
  image_t image_id = 0;
  std::size_t num_shared_points = 0;
  double triangulation_angle_deg = 0.0;
};

// Every other image sharing at least one sparse point with the reference and
// passing the angle test, sorted by num_shared_points (descending), ties by
// image_id (ascending) so the order never depends on container order.
// Shared points are found through the reference's points2D and the tracks of
// their points3D; a point counts once per pair even if observed twice, and
// track elements naming images absent from the model are ignored.
// Throws std::invalid_argument when the reference is not in the model or the
// options fail Check(). An image observing no points gives an empty list.
std::vector<SourceViewCandidate> RankSourceViews(const SparseModel& model,
                                                 image_t reference_image_id,
                                                 const ViewSelectionOptions& options = {});

// The first `max_num_source_views` images of RankSourceViews (fewer if fewer
// qualify): what `__auto__, max_num_source_views` means in patch-match.cfg.
std::vector<image_t> SelectSourceViews(const SparseModel& model,
                                       image_t reference_image_id,
                                       std::size_t max_num_source_views,
                                       const ViewSelectionOptions& options = {});

// True when some point3D observed by the reference (through its points2D) is
// also observed by another image of the model: the condition for
// RankSourceViews to have anything to rank. Throws std::invalid_argument
// when the reference is not in the model.
bool SharesSparsePoints(const SparseModel& model, image_t reference_image_id);

struct PoseSourceViewCandidate {
  image_t image_id = 0;
  // Frustum samples of the reference (see below) this image sees.
  std::size_t num_shared_samples = 0;
  // Percentile (triangulation_angle_percentile) of the samples' angles.
  double triangulation_angle_deg = 0.0;
  // Angle between the two optical axes.
  double viewing_angle_deg = 0.0;
};

// Source-view ranking from the camera poses alone, for references without
// shared sparse points. The reference's frustum is sampled with
// kPoseSampleGrid x kPoseSampleGrid pixels (centres of an even grid over the
// image) back-projected to kPoseSampleDepths depths spaced geometrically over
// [depth_min, depth_max] (camera-frame z). Every other image whose optical
// axis is within max_viewing_angle_deg of the reference's and that sees at
// least one sample, with the triangulation-angle percentile of the samples
// it sees reaching min_triangulation_angle_deg, is a candidate; candidates
// are sorted by num_shared_samples (descending), ties by image_id: the rule
// of RankSourceViews with virtual points. So a view at the reference's
// centre (every angle 0) and a view looking away (sees no sample) are never
// chosen, and among views beside the reference the nearer ones, whose frusta
// overlap it more, come first.
// Throws std::invalid_argument when the reference is not in the model, the
// options fail Check(), or not 0 < depth_min <= depth_max (finite); the
// cameras must be pinhole ones (Camera::CalibrationMatrix throws otherwise).
inline constexpr int kPoseSampleGrid = 8;
inline constexpr int kPoseSampleDepths = 12;
std::vector<PoseSourceViewCandidate> RankSourceViewsByPose(
    const SparseModel& model, image_t reference_image_id, double depth_min, double depth_max,
    const ViewSelectionOptions& options = {});

// The first `max_num_source_views` images of RankSourceViewsByPose.
std::vector<image_t> SelectSourceViewsByPose(const SparseModel& model,
                                             image_t reference_image_id,
                                             std::size_t max_num_source_views, double depth_min,
                                             double depth_max,
                                             const ViewSelectionOptions& options = {});

// Depths to sample when nothing in the workspace says how far the scene is:
// [2 s, 100 s], s the median over images of the distance from a camera
// centre to its nearest other centre (the typical baseline). That is the
// scene seen by neighbouring views under about 28 down to 0.6 degrees,
// which covers how photo collections and videos for MVS are taken. Nullopt
// for fewer than two images or when the typical baseline is 0 (all
// centres equal: nothing can be triangulated).
std::optional<std::pair<double, double>> GuessSampleDepthsFromPoses(const SparseModel& model);

// The depths the pose-based selection samples for a reference when the user
// gives none: the reference's own valid range in `ranges` (its sparse
// points), else the union of the valid ones (FallbackDepthRange), else
// GuessSampleDepthsFromPoses, computed once on first need and kept (it is
// quadratic in the number of images). Nullopt when even the guess fails.
// Keeps references to `model` and `ranges`: they must outlive it.
class PoseSampleDepths {
 public:
  PoseSampleDepths(const SparseModel& model, const std::map<image_t, DepthRange>& ranges);
  std::optional<std::pair<double, double>> For(image_t reference_image_id);
  // The guess, when For needed it and it succeeded.
  const std::optional<std::pair<double, double>>& guessed() const { return guessed_; }

 private:
  const SparseModel& model_;
  const std::map<image_t, DepthRange>& ranges_;
  DepthRange fallback_;
  bool guess_tried_ = false;
  std::optional<std::pair<double, double>> guessed_;
};

}  // namespace dispmvs::colmap_io
