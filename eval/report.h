#pragma once
// The printed table and the JSON file of dispmvs_eval.
//
// Table (fractions as percent with 2 decimals, abs_rel and med_rel as
// fractions with 4, distances with 5 significant digits; "n/a" where a value
// is undefined, e.g. no prediction at all; columns sized to their contents):
//
//   workspace: WS
//   depth maps vs ground truth: 2 of 2 images have ground truth
//   (pred: of the GT pixels with a prediction; all: of all GT pixels)
//   type               views  coverage  abs_rel  med_rel  <1%pred  <2%pred  <5%pred  <1%all  <2%all  <5%all
//   dispmvs.geometric    2/2    50.00%   0.0150   0.0150    0.00%  100.00%  100.00%   0.00%  50.00%  50.00%
//   photometric        no maps
//
// With per_view, one row per view follows its type's row (image name
// indented two spaces, empty views cell). A note line follows the table for
// each type with maps of images that have no ground truth.
//
// When some image with ground truth has a rectified partner (rectified_pair.h)
// a second legend line follows the first and five disparity columns end each
// row (depth_metrics.h): disp_err (mean disparity error in GT pixels, 3
// decimals), <1pxpred, <2pxpred, <1pxall, <2pxall; "n/a" for views without a
// partner and for types none of whose views has one. Without any rectified
// pair the table is exactly as above. With clouds:
//
//   point clouds vs ground truth: GT WS/ground_truth/points.ply, 4 points, bounding-box diagonal 1.7321
//   (distances in scene units; tau 0.0034641 (0.2% of the diagonal), outlier cut-off 0.034641 (2% of the diagonal))
//   ply           points  accuracy  completeness  overall  acc_cut  comp_cut  precision  recall  F-score
//   WS/fused.ply       3         0             0        0        1         2     66.67%  50.00%   57.14%
//
// The JSON file holds the same numbers unrounded (see WriteJsonReport), the
// TSV file the sums behind them (see ReportToTsv).

#include <filesystem>
#include <ostream>
#include <string>

#include "eval/workspace_eval.h"

namespace dispmvs::eval {

void PrintReport(const WorkspaceEvalReport& report, bool per_view, std::ostream& out);

// The report as a JSON document (UTF-8, 2-space indented, NaN as null):
// {"workspace", "num_images", "views_with_gt", "views_with_rectified_partner",
//  "depth": [{"type", "views", "maps_without_gt", "disparity_views",
//             "overall": METRICS or null,
//             "per_view": [{"image", "width", "height", "gt_width", "gt_height",
//                           "rectified_partner", "baseline", "disparity_focal",
//                           ...METRICS}]}],
//  "gt_cloud": null or {"source", "points", "nonfinite_dropped", "bbox_diagonal",
//                       "tau", "cutoff", "tau_relative", "cutoff_relative"},
//  "clouds": [{"ply", "points", "gt_points", "nonfinite_dropped", "tau", "cutoff",
//              "accuracy", "completeness", "overall", "accuracy_cut",
//              "completeness_cut", "precision", "recall", "fscore"}]}
// METRICS: "gt_pixels", "predicted_pixels", "predicted_without_gt", "coverage",
// "abs_rel", "median_rel", "within_{1,2,5}_of_predicted",
// "within_{1,2,5}_of_gt" (fractions, not percent), then the disparity metrics
// (depth_metrics.h) "disparity_gt_pixels", "disparity_predicted_pixels",
// "disparity_mean_error" (GT pixels), "disparity_within_{1,2}px_of_predicted",
// "disparity_within_{1,2}px_of_gt" (fractions), all null where not applicable.
// "disparity_views": views of the type with a rectified partner (those the
// overall disparity metrics cover). Per view, "rectified_partner" (image
// name), "baseline" (model units) and "disparity_focal" (fx at the GT's
// resolution) are null without a partner.
std::string ReportToJson(const WorkspaceEvalReport& report);

// ReportToJson written atomically (atomic_file.h); IoError naming `path`.
void WriteJsonReport(const WorkspaceEvalReport& report, const std::filesystem::path& path);

// A summary a shell script can add up exactly over many workspaces, e.g.
// awk -F'\t' '$1 == "depth" { gt += $4; w2 += $7 } END { print w2 / gt }'.
// Tab-separated, one record per line; lines starting with '#' are comments,
// among them a header with the column names before each kind of record:
//
//   #depth TYPE views gt_pixels predicted within_1 within_2 within_5 abs_rel_sum
//          disparity_gt_pixels disparity_within_1px disparity_within_2px
//   #cloud PLY points gt_points accuracy completeness overall precision recall
//          fscore tau cutoff
//
// (each header one line, its first field "#depth" / "#cloud" and then the
// column names; records start with "depth" / "cloud"). One depth record per
// TYPE in table order, also for types without maps (views 0); the counts are
// the DepthMetricSums / DisparityMetricSums summed over the type's views
// (integers), abs_rel_sum is printed with %.17g, and the disparity counts
// cover the views with a rectified partner (0 where there is none). One cloud
// record per --ply, its distances and fractions with %.17g ("nan" for NaN).
// Overall numbers follow exactly: coverage = predicted / gt_pixels, abs_rel =
// abs_rel_sum / predicted, <X%all = within_X / gt_pixels, <Npx all =
// disparity_within_Npx / disparity_gt_pixels. Throws std::invalid_argument
// when a type or PLY path contains a tab or a line break.
std::string ReportToTsv(const WorkspaceEvalReport& report);

// ReportToTsv written atomically (atomic_file.h); IoError naming `path`.
void WriteTsvReport(const WorkspaceEvalReport& report, const std::filesystem::path& path);

}  // namespace dispmvs::eval
