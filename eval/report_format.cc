#include "eval/report_format.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "model/json.h"

namespace dispmvs::eval::report_format {


std::string Format(const char* format, double value) {
  if (!std::isfinite(value)) return "n/a";
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, format, value);
  return buffer;
}

std::string Percent(double fraction) { return Format("%.2f%%", 100.0 * fraction); }
std::string Fraction(double value) { return Format("%.4f", value); }
std::string Distance(double value) { return Format("%.5g", value); }

// Left-aligned first column, the others right-aligned; two spaces between
// columns. A row with fewer cells ends early (e.g. "no maps").
void PrintTable(const std::vector<Row>& rows, std::ostream& out) {
  std::vector<std::size_t> widths;
  for (const Row& row : rows) {
    if (row.size() < 3) continue;  // short rows do not set widths
    widths.resize(std::max(widths.size(), row.size()), 0);
    for (std::size_t i = 0; i < row.size(); ++i) widths[i] = std::max(widths[i], row[i].size());
  }
  for (const Row& row : rows) {
    if (!widths.empty()) widths[0] = std::max(widths[0], row.empty() ? 0 : row[0].size());
  }
  for (const Row& row : rows) {
    std::string line;
    for (std::size_t i = 0; i < row.size(); ++i) {
      const std::size_t width = i < widths.size() ? widths[i] : 0;
      const std::size_t pad = width > row[i].size() ? width - row[i].size() : 0;
      if (i == 0) {
        line += row[i];
        if (row.size() > 1) line += std::string(pad, ' ');
      } else if (row.size() < 3) {
        line += "  " + row[i];  // free text after the name
      } else {
        line += "  " + std::string(pad, ' ') + row[i];
      }
    }
    out << line << '\n';
  }
}

std::string JsonNumber(double value) {
  if (!std::isfinite(value)) return "null";
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.10g", value);
  return buffer;
}

std::string JsonNumber(int64_t value) { return std::to_string(value); }

JsonObject& JsonObject::Add(const std::string& key, const std::string& raw_value) {
  members_.push_back(std::string(indent_ + 2, ' ') + model::json::Quote(key) + ": " + raw_value);
  return *this;
}

std::string JsonObject::str() const {
  if (members_.empty()) return "{}";
  std::string out = "{\n";
  for (std::size_t i = 0; i < members_.size(); ++i) {
    out += members_[i] + (i + 1 < members_.size() ? ",\n" : "\n");
  }
  return out + std::string(indent_, ' ') + "}";
}

std::string JsonArray(const std::vector<std::string>& items, int indent) {
  if (items.empty()) return "[]";
  std::string out = "[\n";
  for (std::size_t i = 0; i < items.size(); ++i) {
    out += std::string(indent + 2, ' ') + items[i] + (i + 1 < items.size() ? ",\n" : "\n");
  }
  return out + std::string(indent, ' ') + "]";
}

}  // namespace dispmvs::eval::report_format
