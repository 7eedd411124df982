#pragma once
// Formatting shared by dispmvs_eval's reports (eval/report.h and
// eval/comparison_report.h): table cells, an aligned text table, and a
// small JSON writer (values as raw text, NaN and Inf as null).

#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

namespace dispmvs::eval::report_format {

using Row = std::vector<std::string>;

// printf-style with one double; "n/a" for NaN or Inf.
std::string Format(const char* format, double value);
std::string Percent(double fraction);  // "12.34%"
std::string Fraction(double value);    // "0.1234"
std::string Distance(double value);    // 5 significant digits

// Left-aligned first column, the others right-aligned; two spaces between
// columns. A row with fewer than 3 cells is free text after the name and
// does not set the widths (e.g. "no maps").
void PrintTable(const std::vector<Row>& rows, std::ostream& out);

std::string JsonNumber(double value);  // %.10g; null for NaN or Inf
std::string JsonNumber(int64_t value);

// Members of one object, joined with commas at the given indent.
class JsonObject {
 public:
  explicit JsonObject(int indent) : indent_(indent) {}
  JsonObject& Add(const std::string& key, const std::string& raw_value);
  std::string str() const;

 private:
  int indent_;
  std::vector<std::string> members_;
};

std::string JsonArray(const std::vector<std::string>& items, int indent);

}  // namespace dispmvs::eval::report_format
