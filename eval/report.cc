#include "eval/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "colmap_io/atomic_file.h"
#include "eval/report_format.h"
#include "model/json.h"

namespace dispmvs::eval {
namespace {

using namespace report_format;

Row MetricCells(const std::string& name, const std::string& views, const DepthMetrics& m) {
  return {name,
          views,
          Percent(m.coverage),
          Fraction(m.abs_rel),
          Fraction(m.median_rel),
          Percent(m.within_1_of_predicted),
          Percent(m.within_2_of_predicted),
          Percent(m.within_5_of_predicted),
          Percent(m.within_1_of_gt),
          Percent(m.within_2_of_gt),
          Percent(m.within_5_of_gt)};
}

// Not applicable (no rectified partner) comes out as "n/a": every value is NaN.
void AppendDisparityCells(const DisparityMetrics& m, Row* row) {
  row->insert(row->end(), {Format("%.3f", m.mean_error), Percent(m.within_1px_of_predicted),
                           Percent(m.within_2px_of_predicted), Percent(m.within_1px_of_gt),
                           Percent(m.within_2px_of_gt)});
}

// The confidence maps' ranking, for the types that have them.
void PrintConfidenceRanking(const WorkspaceEvalReport& report, std::ostream& out) {
  std::vector<Row> rows;
  rows.push_back({"type", "views", "pixels"});
  for (const double coverage : kRankingCoverages) rows.back().push_back(Format("%g%%", 100 * coverage));
  for (const TypeDepthResult& type : report.types) {
    if (type.views_with_confidence == 0) continue;
    rows.push_back({type.type, std::to_string(type.views_with_confidence) + "/" + std::to_string(type.views.size()),
                    std::to_string(type.confidence_ranking.total())});
    for (const double coverage : kRankingCoverages) {
      rows.back().push_back(Percent(type.confidence_ranking.ShareWithin2AtCoverage(coverage)));
    }
  }
  if (rows.size() == 1) return;
  out << "\nconfidence ranking: of the predicted pixels with ground truth, the share within 2 % among "
         "the most confident 50 / 75 / 90 / 100 % (falling = the confidence keeps the right pixels first)\n";
  PrintTable(rows, out);
}

// With --regions: each type's pixels by region (error_regions.h).
void PrintErrorRegions(const WorkspaceEvalReport& report, std::ostream& out) {
  std::vector<Row> rows;
  rows.push_back({"type", "region", "share", "<1%all", "<2%all", "<5%all"});
  for (const TypeDepthResult& type : report.types) {
    if (type.regions.gt_pixels == 0) continue;
    for (const auto& [name, sums] : RegionRows(type.regions)) {
      const auto share = [&](int64_t count, int64_t of) {
        return Percent(of > 0 ? static_cast<double>(count) / static_cast<double>(of) : std::nan(""));
      };
      rows.push_back({type.type, name, share(sums.gt_pixels, type.regions.gt_pixels),
                      share(sums.within_1, sums.gt_pixels), share(sums.within_2, sums.gt_pixels),
                      share(sums.within_5, sums.gt_pixels)});
    }
  }
  if (rows.size() == 1) return;
  out << "\nerror regions: the GT pixels by whether another view with GT sees them (hidden: behind a "
         "nearer surface there), the seen ones by their distance to the nearest GT depth edge; share of "
         "all GT pixels, and the class's pixels within 1 / 2 / 5 % (a missing prediction = miss)\n";
  PrintTable(rows, out);
}

// ---- TSV ----

// Exact and round-trippable: 17 significant digits, "nan" for NaN.
std::string TsvNumber(double value) {
  if (std::isnan(value)) return "nan";
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.17g", value);
  return buffer;
}

// A field must not contain the separators of the format.
const std::string& TsvField(const std::string& text, const char* what) {
  if (text.find_first_of("\t\n\r") != std::string::npos) {
    throw std::invalid_argument(std::string(what) + " \"" + text +
                                "\" contains a tab or a line break and cannot be written to the "
                                "TSV file");
  }
  return text;
}

// ---- JSON ----

void AddDisparityMetrics(const DisparityMetrics& m, JsonObject* object) {
  const auto count = [&](int64_t value) {
    return m.applicable ? JsonNumber(value) : std::string("null");
  };
  object->Add("disparity_gt_pixels", count(m.gt_pixels))
      .Add("disparity_predicted_pixels", count(m.predicted))
      .Add("disparity_mean_error", JsonNumber(m.mean_error))
      .Add("disparity_within_1px_of_predicted", JsonNumber(m.within_1px_of_predicted))
      .Add("disparity_within_2px_of_predicted", JsonNumber(m.within_2px_of_predicted))
      .Add("disparity_within_1px_of_gt", JsonNumber(m.within_1px_of_gt))
      .Add("disparity_within_2px_of_gt", JsonNumber(m.within_2px_of_gt));
}

void AddMetrics(const DepthMetrics& m, JsonObject* object) {
  object->Add("gt_pixels", JsonNumber(m.gt_pixels))
      .Add("predicted_pixels", JsonNumber(m.predicted))
      .Add("predicted_without_gt", JsonNumber(m.predicted_without_gt))
      .Add("coverage", JsonNumber(m.coverage))
      .Add("abs_rel", JsonNumber(m.abs_rel))
      .Add("median_rel", JsonNumber(m.median_rel))
      .Add("within_1_of_predicted", JsonNumber(m.within_1_of_predicted))
      .Add("within_2_of_predicted", JsonNumber(m.within_2_of_predicted))
      .Add("within_5_of_predicted", JsonNumber(m.within_5_of_predicted))
      .Add("within_1_of_gt", JsonNumber(m.within_1_of_gt))
      .Add("within_2_of_gt", JsonNumber(m.within_2_of_gt))
      .Add("within_5_of_gt", JsonNumber(m.within_5_of_gt));
}

}  // namespace

void PrintReport(const WorkspaceEvalReport& report, bool per_view, std::ostream& out) {
  out << "workspace: " << report.workspace << '\n';
  out << "depth maps vs ground truth: " << report.views_with_gt << " of " << report.num_images
      << " images have ground truth\n";
  out << "(pred: of the GT pixels with a prediction; all: of all GT pixels)\n";
  // Without any rectified pair the table keeps its original columns.
  const bool disparity = report.views_with_rectified_partner > 0;
  if (disparity) {
    out << "(disparity, over the " << report.views_with_rectified_partner
        << " view(s) with a rectified partner: disp_err = mean |f B / d - f B / gt| in GT "
           "pixels; <Npx: error < N px)\n";
  }
  std::vector<Row> rows;
  rows.push_back({"type", "views", "coverage", "abs_rel", "med_rel", "<1%pred", "<2%pred",
                  "<5%pred", "<1%all", "<2%all", "<5%all"});
  if (disparity) {
    rows.back().insert(rows.back().end(),
                       {"disp_err", "<1pxpred", "<2pxpred", "<1pxall", "<2pxall"});
  }
  std::vector<std::string> notes;
  for (const TypeDepthResult& type : report.types) {
    if (!type.evaluated()) {
      rows.push_back({type.type, type.maps_without_gt > 0
                                     ? "no maps for images with ground truth"
                                     : "no maps"});
    } else {
      rows.push_back(MetricCells(
          type.type,
          std::to_string(type.views.size()) + "/" + std::to_string(report.views_with_gt),
          type.overall));
      if (disparity) AppendDisparityCells(type.disparity_overall, &rows.back());
      if (per_view) {
        for (const ViewDepthResult& view : type.views) {
          rows.push_back(MetricCells("  " + view.image_name, "", view.metrics));
          if (disparity) AppendDisparityCells(view.disparity, &rows.back());
        }
      }
    }
    if (type.maps_without_gt > 0) {
      notes.push_back("note: " + type.type + ": " + std::to_string(type.maps_without_gt) +
                      " map(s) of images without ground truth, not scored");
    }
  }
  PrintTable(rows, out);
  for (const std::string& note : notes) out << note << '\n';
  PrintConfidenceRanking(report, out);
  PrintErrorRegions(report, out);

  if (!report.gt_cloud) return;
  const GtCloudInfo& gt = *report.gt_cloud;
  const auto threshold = [&](double value, bool relative, double fraction_of_diagonal) {
    std::string text = Distance(value);
    if (relative) text += " (" + Format("%g", 100.0 * fraction_of_diagonal) + "% of the diagonal)";
    return text;
  };
  const double diagonal = gt.bbox_diagonal > 0 ? gt.bbox_diagonal : 1.0;
  out << "\npoint clouds vs ground truth: GT " << gt.source << ", " << gt.num_points
      << " points, bounding-box diagonal " << Distance(gt.bbox_diagonal) << '\n';
  out << "(distances in scene units; tau "
      << threshold(gt.thresholds.tau, gt.tau_relative, gt.thresholds.tau / diagonal)
      << ", outlier cut-off "
      << threshold(gt.thresholds.cutoff, gt.cutoff_relative, gt.thresholds.cutoff / diagonal)
      << ")\n";
  if (gt.nonfinite_dropped > 0) {
    out << "note: ground truth: " << gt.nonfinite_dropped << " non-finite point(s) ignored\n";
  }
  rows.clear();
  notes.clear();
  rows.push_back({"ply", "points", "accuracy", "completeness", "overall", "acc_cut", "comp_cut",
                  "precision", "recall", "F-score"});
  for (const CloudResult& cloud : report.clouds) {
    const CloudMetrics& m = cloud.metrics;
    rows.push_back({cloud.ply_path, std::to_string(m.num_points), Distance(m.accuracy),
                    Distance(m.completeness), Distance(m.overall), std::to_string(m.accuracy_cut),
                    std::to_string(m.completeness_cut), Percent(m.precision), Percent(m.recall),
                    Percent(m.fscore)});
    if (cloud.nonfinite_dropped > 0) {
      notes.push_back("note: " + cloud.ply_path + ": " + std::to_string(cloud.nonfinite_dropped) +
                      " non-finite point(s) ignored");
    }
  }
  PrintTable(rows, out);
  for (const std::string& note : notes) out << note << '\n';
}

std::string ReportToJson(const WorkspaceEvalReport& report) {
  JsonObject root(0);
  root.Add("workspace", model::json::Quote(report.workspace))
      .Add("num_images", JsonNumber(static_cast<int64_t>(report.num_images)))
      .Add("views_with_gt", JsonNumber(static_cast<int64_t>(report.views_with_gt)))
      .Add("views_with_rectified_partner",
           JsonNumber(static_cast<int64_t>(report.views_with_rectified_partner)));
  std::vector<std::string> types;
  for (const TypeDepthResult& type : report.types) {
    JsonObject object(4);
    object.Add("type", model::json::Quote(type.type))
        .Add("views", JsonNumber(static_cast<int64_t>(type.views.size())))
        .Add("maps_without_gt", JsonNumber(type.maps_without_gt))
        .Add("disparity_views", JsonNumber(type.disparity_sums.views));
    if (type.views_with_confidence > 0) {
      JsonObject ranking(6);
      ranking.Add("views", JsonNumber(static_cast<int64_t>(type.views_with_confidence)))
          .Add("pixels", JsonNumber(type.confidence_ranking.total()));
      for (const double coverage : kRankingCoverages) {
        ranking.Add(Format("within_2_at_%g", 100 * coverage),
                    JsonNumber(type.confidence_ranking.ShareWithin2AtCoverage(coverage)));
      }
      object.Add("confidence_ranking", ranking.str());
    }
    if (type.evaluated()) {
      JsonObject overall(6);
      AddMetrics(type.overall, &overall);
      AddDisparityMetrics(type.disparity_overall, &overall);
      object.Add("overall", overall.str());
    } else {
      object.Add("overall", "null");
    }
    std::vector<std::string> views;
    for (const ViewDepthResult& view : type.views) {
      JsonObject v(8);
      v.Add("image", model::json::Quote(view.image_name))
          .Add("width", JsonNumber(static_cast<int64_t>(view.width)))
          .Add("height", JsonNumber(static_cast<int64_t>(view.height)))
          .Add("gt_width", JsonNumber(static_cast<int64_t>(view.gt_width)))
          .Add("gt_height", JsonNumber(static_cast<int64_t>(view.gt_height)));
      if (view.disparity_geometry) {
        const DisparityGeometry& geometry = *view.disparity_geometry;
        v.Add("rectified_partner", model::json::Quote(geometry.partner.name))
            .Add("baseline", JsonNumber(geometry.partner.baseline))
            .Add("disparity_focal", JsonNumber(geometry.focal));
      } else {
        v.Add("rectified_partner", "null").Add("baseline", "null").Add("disparity_focal", "null");
      }
      AddMetrics(view.metrics, &v);
      AddDisparityMetrics(view.disparity, &v);
      views.push_back(v.str());
    }
    object.Add("per_view", JsonArray(views, 6));
    types.push_back(object.str());
  }
  root.Add("depth", JsonArray(types, 2));
  if (report.gt_cloud) {
    const GtCloudInfo& gt = *report.gt_cloud;
    JsonObject object(2);
    object.Add("source", model::json::Quote(gt.source))
        .Add("points", JsonNumber(gt.num_points))
        .Add("nonfinite_dropped", JsonNumber(gt.nonfinite_dropped))
        .Add("bbox_diagonal", JsonNumber(gt.bbox_diagonal))
        .Add("tau", JsonNumber(gt.thresholds.tau))
        .Add("cutoff", JsonNumber(gt.thresholds.cutoff))
        .Add("tau_relative", gt.tau_relative ? "true" : "false")
        .Add("cutoff_relative", gt.cutoff_relative ? "true" : "false");
    root.Add("gt_cloud", object.str());
  } else {
    root.Add("gt_cloud", "null");
  }
  std::vector<std::string> clouds;
  for (const CloudResult& cloud : report.clouds) {
    const CloudMetrics& m = cloud.metrics;
    JsonObject object(4);
    object.Add("ply", model::json::Quote(cloud.ply_path))
        .Add("points", JsonNumber(m.num_points))
        .Add("gt_points", JsonNumber(m.num_gt_points))
        .Add("nonfinite_dropped", JsonNumber(cloud.nonfinite_dropped))
        .Add("tau", JsonNumber(m.tau))
        .Add("cutoff", JsonNumber(m.cutoff))
        .Add("accuracy", JsonNumber(m.accuracy))
        .Add("completeness", JsonNumber(m.completeness))
        .Add("overall", JsonNumber(m.overall))
        .Add("accuracy_cut", JsonNumber(m.accuracy_cut))
        .Add("completeness_cut", JsonNumber(m.completeness_cut))
        .Add("precision", JsonNumber(m.precision))
        .Add("recall", JsonNumber(m.recall))
        .Add("fscore", JsonNumber(m.fscore));
    clouds.push_back(object.str());
  }
  root.Add("clouds", JsonArray(clouds, 2));
  return root.str() + "\n";
}

void WriteJsonReport(const WorkspaceEvalReport& report, const std::filesystem::path& path) {
  const std::string json = ReportToJson(report);
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) { out << json; });
}

std::string ReportToTsv(const WorkspaceEvalReport& report) {
  std::string workspace = report.workspace;
  for (char& c : workspace) {
    if (c == '\n' || c == '\r') c = ' ';  // it is only a comment
  }
  std::string out = "# dispmvs_eval summary of " + workspace + "\n";
  out += "# counts are pixel counts summed over the views; abs_rel_sum is the sum of |d - gt| / "
         "gt over the predicted pixels\n";
  out += std::string("#depth\ttype\tviews\tgt_pixels\tpredicted\twithin_1\twithin_2\twithin_5\t") +
         "abs_rel_sum\tdisparity_gt_pixels\tdisparity_within_1px\tdisparity_within_2px\n";
  for (const TypeDepthResult& type : report.types) {
    const DepthMetricSums& s = type.sums;
    const DisparityMetricSums& d = type.disparity_sums;
    out += "depth\t" + TsvField(type.type, "depth-map type") + "\t" +
           std::to_string(type.views.size()) + "\t" + std::to_string(s.gt_pixels) + "\t" +
           std::to_string(s.predicted) + "\t" + std::to_string(s.within_1) + "\t" +
           std::to_string(s.within_2) + "\t" + std::to_string(s.within_5) + "\t" +
           TsvNumber(s.abs_rel_sum) + "\t" + std::to_string(d.gt_pixels) + "\t" +
           std::to_string(d.within_1px) + "\t" + std::to_string(d.within_2px) + "\n";
  }
  out += "#confidence\ttype\tviews\tpixels\twithin_2_at_50\twithin_2_at_75\twithin_2_at_90\twithin_2_at_100\n";
  for (const TypeDepthResult& type : report.types) {
    if (type.views_with_confidence == 0) continue;
    out += "confidence\t" + TsvField(type.type, "depth-map type") + "\t" +
           std::to_string(type.views_with_confidence) + "\t" + std::to_string(type.confidence_ranking.total());
    for (const double coverage : kRankingCoverages) {
      out += "\t" + TsvNumber(type.confidence_ranking.ShareWithin2AtCoverage(coverage));
    }
    out += "\n";
  }
  out += "#region\ttype\tregion\tgt_pixels\twithin_1\twithin_2\twithin_5\n";
  for (const TypeDepthResult& type : report.types) {
    if (type.regions.gt_pixels == 0) continue;
    for (const auto& [name, sums] : RegionRows(type.regions)) {
      out += "region\t" + TsvField(type.type, "depth-map type") + "\t" + name + "\t" + std::to_string(sums.gt_pixels) +
             "\t" + std::to_string(sums.within_1) + "\t" + std::to_string(sums.within_2) + "\t" +
             std::to_string(sums.within_5) + "\n";
    }
  }
  out += "#cloud\tply\tpoints\tgt_points\taccuracy\tcompleteness\toverall\tprecision\trecall\t"
         "fscore\ttau\tcutoff\n";
  for (const CloudResult& cloud : report.clouds) {
    const CloudMetrics& m = cloud.metrics;
    out += "cloud\t" + TsvField(cloud.ply_path, "point-cloud path") + "\t" +
           std::to_string(m.num_points) + "\t" + std::to_string(m.num_gt_points);
    for (const double value :
         {m.accuracy, m.completeness, m.overall, m.precision, m.recall, m.fscore, m.tau, m.cutoff}) {
      out += "\t" + TsvNumber(value);
    }
    out += "\n";
  }
  return out;
}

void WriteTsvReport(const WorkspaceEvalReport& report, const std::filesystem::path& path) {
  const std::string tsv = ReportToTsv(report);
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) { out << tsv; });
}

}  // namespace dispmvs::eval
