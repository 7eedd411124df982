#pragma once
// The run report: one self-contained HTML file (images embedded, no script,
// nothing fetched) to look at a dense workspace without writing code. Per
// registered image: the image, the time the network took on it, our
// photometric and geometric depth maps (colourised on one scale per view, the
// 2nd to 98th percentile of the first map's depths, with its colour bar and
// range), the normal and confidence maps, each map's coverage, and
// PatchMatch's maps beside ours where `colmap patch_match_stereo` left them
// (NAME.photometric.bin, NAME.geometric.bin); for the workspace, the fused
// cloud's size and three orthographic pictures of it, the settings used, and
// the photometric pass's time per view and in all (colmap_io/view_record.h).
// Thumbnails are small JPEGs (about 5 KB each) loaded lazily, so a report of
// a thousand images stays near 30 MB and opens quickly.

#include <cstddef>
#include <filesystem>
#include <string>

namespace dispmvs::eval {

struct HtmlReportOptions {
  int thumbnail_width = 160;   // pixels; heights keep each image's aspect
  int cloud_view_size = 360;   // pixels of each cloud picture
  std::string ply_path;        // empty: WS/fused.ply (left out if absent)
  std::string settings;        // shown verbatim, e.g. the command line
  void Check() const;          // std::invalid_argument naming the field
};

struct HtmlReportSummary {
  int views = 0;            // registered images
  int embedded_images = 0;  // <img> elements
  std::size_t bytes = 0;    // of the HTML file
};

// Reads the workspace and writes the report to `html_path` atomically.
// Throws IoError for an unreadable workspace, map or cloud.
HtmlReportSummary WriteHtmlReport(const std::filesystem::path& workspace_path,
                                  const std::filesystem::path& html_path,
                                  const HtmlReportOptions& options);

}  // namespace dispmvs::eval
