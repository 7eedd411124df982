#pragma once
// Evaluation of a whole workspace: every depth-map TYPE against the ground
// truth, and point clouds against a ground-truth cloud. dispmvs_eval is a thin
// command line around EvaluateWorkspace() and the report functions.
//
// Workspace layout (a COLMAP dense workspace plus our ground truth):
//   WS/sparse/                             cameras and poses (PINHOLE / SIMPLE_PINHOLE)
//   WS/images/
//   WS/stereo/depth_maps/NAME.TYPE.bin     maps to evaluate, any TYPE
//   WS/ground_truth/depth_maps/NAME.bin    GT depth at image size (0 = no surface)
//   WS/ground_truth/points.ply             optional GT cloud (fused.ply layout)
// Images are those of the sparse model, in name order. A GT map must be the
// size of its camera (or a clean down-scale of it); a depth map must be a
// clean down-scale of its GT map (depth_metrics.h has the pixel convention).
// An image with GT that forms a rectified pair with another registered image
// (rectified_pair.h) is also scored in disparity (depth_metrics.h), with its
// partner's baseline.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "colmap_io/sparse_model.h"
#include "colmap_io/workspace.h"
#include "eval/cloud_metrics.h"
#include "eval/confidence_ranking.h"
#include "eval/depth_metrics.h"
#include "eval/error_regions.h"
#include "eval/rectified_pair.h"

namespace dispmvs::eval {

struct WorkspaceEvalOptions {
  // Depth-map types to evaluate; empty: every TYPE found under
  // WS/stereo/depth_maps (DiscoverDepthMapTypes).
  std::vector<std::string> types;
  // Point clouds (fused.ply layout) to evaluate against the GT cloud.
  std::vector<std::string> ply_paths;
  // When not empty: colourised depth and relative-error PNGs go here.
  std::string png_dir;
  // Precision/recall threshold and outlier cut-off in scene units; 0 = the
  // *_relative fraction of the GT cloud's bounding-box diagonal.
  double tau = 0;
  double cutoff = 0;
  double tau_relative = 0.002;
  double cutoff_relative = 0.02;
  // GT cloud from GT depth maps (when WS/ground_truth/points.ply is absent):
  // every gt_stride-th column and row.
  int gt_stride = 1;
  // Relative error shown at the top of the error PNGs' colour scale.
  double png_max_rel_error = 0.05;
  // Split each type's metrics by where the pixels lie (error_regions.h):
  // seen by another view with GT, hidden there, outside it; seen pixels by
  // distance to the nearest GT depth edge. Reads every GT map first and keeps
  // them all in memory (each view is labelled against all the others).
  bool regions = false;

  void Check() const;  // std::invalid_argument naming the field
};

// The rectified partner of an image with GT (rectified_pair.h) and the
// factor that turns its depth into disparity in GT pixels.
struct DisparityGeometry {
  RectifiedPartner partner;
  double focal = 0;  // the camera's fx scaled to the GT map's width
};

struct ViewDepthResult {
  std::string image_name;
  int width = 0, height = 0;        // the depth map's
  int gt_width = 0, gt_height = 0;  // the GT map's
  DepthMetrics metrics;
  std::optional<DisparityGeometry> disparity_geometry;  // none: no rectified partner
  DisparityMetrics disparity;                           // not applicable without one
};

struct TypeDepthResult {
  std::string type;
  std::vector<ViewDepthResult> views;  // images with GT and a map of this type
  int64_t maps_without_gt = 0;         // maps of images without GT (not scored)
  // Images with GT but no map of this type whose dispmvs_colmap run failed,
  // with the reason its view record (colmap_io/view_record.h) gives.
  struct FailedView {
    std::string image_name, reason;
  };
  std::vector<FailedView> failed_views;
  DepthMetrics overall;                // pixel-weighted over `views`
  // The pixel-weighted disparity numbers of the views that have a rectified
  // partner (not applicable when none has).
  DisparityMetrics disparity_overall;
  // The raw sums behind `overall` and `disparity_overall` (the TSV report).
  DepthMetricSums sums;
  DisparityMetricSums disparity_sums;
  // The confidence maps' ranking of the predicted pixels
  // (confidence_ranking.h), over the views that have one of the depth map's
  // size; views_with_confidence of `views` had one.
  ConfidenceRankingSums confidence_ranking;
  int views_with_confidence = 0;
  // With WorkspaceEvalOptions::regions: the metrics' pixels by region.
  ErrorRegionSums regions;
  bool evaluated() const { return !views.empty(); }
};

struct GtCloudInfo {
  std::string source;  // the PLY path, or "ground-truth depth maps (stride N)"
  int64_t num_points = 0;
  int64_t nonfinite_dropped = 0;
  double bbox_diagonal = 0;
  CloudMetricOptions thresholds;
  bool tau_relative = false;     // tau derived from the diagonal
  bool cutoff_relative = false;  // cut-off derived from the diagonal
};

struct CloudResult {
  std::string ply_path;
  int64_t nonfinite_dropped = 0;  // non-finite points in the file, not used
  CloudMetrics metrics;
};

struct WorkspaceEvalReport {
  std::string workspace;
  int num_images = 0;       // registered images of the sparse model
  int views_with_gt = 0;    // ... with a GT depth map
  int views_with_rectified_partner = 0;  // ... of those, with a rectified partner
  std::vector<TypeDepthResult> types;
  std::optional<GtCloudInfo> gt_cloud;  // when ply_paths was not empty
  std::vector<CloudResult> clouds;
  int64_t png_files = 0;
};

// WS/ground_truth/depth_maps and WS/ground_truth/points.ply.
std::filesystem::path GroundTruthDepthDir(const colmap_io::Workspace& workspace);
std::filesystem::path GroundTruthCloudPath(const colmap_io::Workspace& workspace);

// Every TYPE with at least one file WS/stereo/depth_maps/NAME.TYPE.bin for an
// image NAME of `model`, sorted. A file whose name several image names
// prefix (names contain dots) belongs to the longest; files matching no image
// are ignored.
std::vector<std::string> DiscoverDepthMapTypes(const colmap_io::Workspace& workspace,
                                               const colmap_io::SparseModel& model);

// Reads and scores everything. Throws IoError (naming the file) or
// std::invalid_argument for bad input: no workspace, no GT depth map for any
// image, a map or GT with a bad size or truncated, no map of any requested
// type for an image with GT, a missing or bad PLY, an empty GT cloud. Types
// without maps are reported with no views, not an error (unless all are).
WorkspaceEvalReport EvaluateWorkspace(const std::filesystem::path& workspace_path,
                                      const WorkspaceEvalOptions& options);

}  // namespace dispmvs::eval
