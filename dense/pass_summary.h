#pragma once
// What a pass of dispmvs_colmap reports (views done, skipped, failed, time),
// and the small formatters its progress lines share.

#include <chrono>
#include <cstddef>
#include <string>
#include <vector>

namespace dispmvs::dense {

struct PassSummary {
  int done = 0;
  int skipped_existing = 0;
  int skipped_no_sources = 0;
  // Views another process was computing at the time (dense/view_claim.h).
  int skipped_claimed = 0;
  std::vector<std::string> failures;  // "NAME: why"
  double seconds = 0;
};

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start);
// "H:MM:SS", rounded to the second (negative durations read as 0).
std::string FormatDuration(double seconds);
// "1.23 s".
std::string FormatSeconds(double seconds);
// "12.3 MB" for 12.3 x 2^20 bytes.
std::string FormatMegabytes(std::size_t bytes);
// "12.3%" for 0.123.
std::string Percent(double fraction);

}  // namespace dispmvs::dense
