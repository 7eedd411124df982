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
// each type with maps of images that have no ground truth. With clouds:
//
//   point clouds vs ground truth: GT WS/ground_truth/points.ply, 4 points, bounding-box diagonal 1.7321
//   (distances in scene units; tau 0.0034641 (0.2% of the diagonal), outlier cut-off 0.034641 (2% of the diagonal))
//   ply           points  accuracy  completeness  overall  acc_cut  comp_cut  precision  recall  F-score
//   WS/fused.ply       3         0             0        0        1         2     66.67%  50.00%   57.14%
//
// The JSON file holds the same numbers unrounded (see WriteJsonReport).

#include <filesystem>
#include <ostream>
#include <string>

#include "eval/workspace_eval.h"

namespace dispmvs::eval {

void PrintReport(const WorkspaceEvalReport& report, bool per_view, std::ostream& out);

// The report as a JSON document (UTF-8, 2-space indented, NaN as null):
// {"workspace", "num_images", "views_with_gt",
//  "depth": [{"type", "views", "maps_without_gt", "overall": METRICS or null,
//             "per_view": [{"image", "width", "height", "gt_width", "gt_height",
//                           ...METRICS}]}],
//  "gt_cloud": null or {"source", "points", "nonfinite_dropped", "bbox_diagonal",
//                       "tau", "cutoff", "tau_relative", "cutoff_relative"},
//  "clouds": [{"ply", "points", "gt_points", "nonfinite_dropped", "tau", "cutoff",
//              "accuracy", "completeness", "overall", "accuracy_cut",
//              "completeness_cut", "precision", "recall", "fscore"}]}
// METRICS: "gt_pixels", "predicted_pixels", "predicted_without_gt", "coverage",
// "abs_rel", "median_rel", "within_{1,2,5}_of_predicted",
// "within_{1,2,5}_of_gt" (fractions, not percent).
std::string ReportToJson(const WorkspaceEvalReport& report);

// ReportToJson written atomically (atomic_file.h); IoError naming `path`.
void WriteJsonReport(const WorkspaceEvalReport& report, const std::filesystem::path& path);

}  // namespace dispmvs::eval
