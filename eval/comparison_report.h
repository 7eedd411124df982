#pragma once
// How dispmvs_eval --compare shows a MethodComparison (eval/method_comparison.h):
// a table with one pooled row (and one per view with --per_view), a line for
// the clouds, and every number in JSON.
//
// Printed columns: views compared, coverage of A and of B, pixels both have,
// agreement within 1 / 2 / 5 % (of the shared pixels), consistency of A and
// of B; all as percentages, "n/a" where nothing was counted.

#include <filesystem>
#include <ostream>
#include <string>

#include "eval/method_comparison.h"

namespace dispmvs::eval {

void PrintComparison(const MethodComparison& report, bool per_view, std::ostream& out);

// {"workspace", "type_a", "type_b", "views_compared", "pooled": {...},
//  "views": [{"name", "has_a", "has_b", "width", "height", "sources_a",
//  "sources_b", counts and fractions}], "clouds": {...} or null}; counts are
// integers, fractions null where undefined.
std::string ComparisonToJson(const MethodComparison& report);
void WriteComparisonJson(const MethodComparison& report, const std::filesystem::path& path);

}  // namespace dispmvs::eval
