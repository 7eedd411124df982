#include "eval/comparison_report.h"

#include <vector>

#include "colmap_io/atomic_file.h"
#include "eval/report_format.h"
#include "model/json.h"

namespace dispmvs::eval {
namespace {

using namespace report_format;

Row Cells(const std::string& name, const std::string& views, const AgreementSums& sums) {
  const Agreement f = Fractions(sums);
  return {name,
          views,
          Percent(f.coverage_a),
          Percent(f.coverage_b),
          Percent(f.shared),
          Percent(f.within_1),
          Percent(f.within_2),
          Percent(f.within_5),
          Percent(f.consistency_a),
          Percent(f.consistency_b)};
}

std::string SumsToJson(const AgreementSums& s, int indent) {
  const Agreement f = Fractions(s);
  JsonObject o(indent);
  o.Add("pixels", JsonNumber(s.pixels))
      .Add("valid_a", JsonNumber(s.valid_a))
      .Add("valid_b", JsonNumber(s.valid_b))
      .Add("shared", JsonNumber(s.shared))
      .Add("within_1", JsonNumber(s.within_1))
      .Add("within_2", JsonNumber(s.within_2))
      .Add("within_5", JsonNumber(s.within_5))
      .Add("checked_a", JsonNumber(s.checked_a))
      .Add("consistent_a", JsonNumber(s.consistent_a))
      .Add("checked_b", JsonNumber(s.checked_b))
      .Add("consistent_b", JsonNumber(s.consistent_b))
      .Add("coverage_a", JsonNumber(f.coverage_a))
      .Add("coverage_b", JsonNumber(f.coverage_b))
      .Add("shared_fraction", JsonNumber(f.shared))
      .Add("within_1_fraction", JsonNumber(f.within_1))
      .Add("within_2_fraction", JsonNumber(f.within_2))
      .Add("within_5_fraction", JsonNumber(f.within_5))
      .Add("consistency_a", JsonNumber(f.consistency_a))
      .Add("consistency_b", JsonNumber(f.consistency_b));
  return o.str();
}

}  // namespace

void PrintComparison(const MethodComparison& report, bool per_view, std::ostream& out) {
  out << "workspace: " << report.workspace << "\ncompare: A = " << report.type_a
      << ", B = " << report.type_b << " (no ground truth: agreement and self-consistency)\n";
  std::vector<Row> rows = {{"", "views", "cov A", "cov B", "both", "<1%", "<2%", "<5%", "cons A",
                            "cons B"}};
  rows.push_back(Cells("all", std::to_string(report.views_compared) + "/" +
                                  std::to_string(report.views.size()),
                       report.pooled));
  if (per_view) {
    for (const ViewComparison& view : report.views) {
      if (view.has_a && view.has_b) {
        rows.push_back(Cells("  " + view.name, "", view.sums));
      } else {
        rows.push_back({"  " + view.name, view.has_a ? "no map of B"
                                          : view.has_b ? "no map of A"
                                                       : "no map of either"});
      }
    }
  }
  PrintTable(rows, out);
  if (report.clouds) {
    const CloudMetrics& m = report.clouds->a_against_b;
    out << "clouds: A = " << report.clouds->ply_a << " (" << m.num_points << " points), B = "
        << report.clouds->ply_b << " (" << m.num_gt_points << " points)\n"
        << "  A -> B mean distance " << Distance(m.accuracy) << ", B -> A " << Distance(m.completeness)
        << " (cut-off " << Distance(m.cutoff) << "); within tau = " << Distance(m.tau) << ": "
        << Percent(m.precision) << " of A, " << Percent(m.recall) << " of B, F-score "
        << Fraction(m.fscore) << '\n';
  }
}

std::string ComparisonToJson(const MethodComparison& report) {
  std::vector<std::string> views;
  for (const ViewComparison& view : report.views) {
    JsonObject o(4);
    o.Add("name", model::json::Quote(view.name))
        .Add("has_a", view.has_a ? "true" : "false")
        .Add("has_b", view.has_b ? "true" : "false")
        .Add("width", JsonNumber(int64_t{view.width}))
        .Add("height", JsonNumber(int64_t{view.height}))
        .Add("sources_a", JsonNumber(int64_t{view.sources_a}))
        .Add("sources_b", JsonNumber(int64_t{view.sources_b}))
        .Add("sums", SumsToJson(view.sums, 4));
    views.push_back(o.str());
  }
  std::string clouds = "null";
  if (report.clouds) {
    const CloudMetrics& m = report.clouds->a_against_b;
    JsonObject o(2);
    o.Add("ply_a", model::json::Quote(report.clouds->ply_a))
        .Add("ply_b", model::json::Quote(report.clouds->ply_b))
        .Add("points_a", JsonNumber(m.num_points))
        .Add("points_b", JsonNumber(m.num_gt_points))
        .Add("nonfinite_dropped_a", JsonNumber(report.clouds->nonfinite_dropped_a))
        .Add("nonfinite_dropped_b", JsonNumber(report.clouds->nonfinite_dropped_b))
        .Add("mean_distance_a_to_b", JsonNumber(m.accuracy))
        .Add("mean_distance_b_to_a", JsonNumber(m.completeness))
        .Add("a_beyond_cutoff", JsonNumber(m.accuracy_cut))
        .Add("b_beyond_cutoff", JsonNumber(m.completeness_cut))
        .Add("tau", JsonNumber(m.tau))
        .Add("cutoff", JsonNumber(m.cutoff))
        .Add("a_within_tau", JsonNumber(m.precision))
        .Add("b_within_tau", JsonNumber(m.recall))
        .Add("fscore", JsonNumber(m.fscore));
    clouds = o.str();
  }
  JsonObject root(0);
  root.Add("workspace", model::json::Quote(report.workspace))
      .Add("type_a", model::json::Quote(report.type_a))
      .Add("type_b", model::json::Quote(report.type_b))
      .Add("views_compared", JsonNumber(int64_t{report.views_compared}))
      .Add("pooled", SumsToJson(report.pooled, 2))
      .Add("views", JsonArray(views, 2))
      .Add("clouds", clouds);
  return root.str() + "\n";
}

void WriteComparisonJson(const MethodComparison& report, const std::filesystem::path& path) {
  const std::string json = ComparisonToJson(report);
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) { out << json; });
}

}  // namespace dispmvs::eval
