#include "eval/html_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "colmap_io/atomic_file.h"
#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/image_io.h"
#include "colmap_io/ply.h"
#include "colmap_io/view_record.h"
#include "colmap_io/workspace.h"
#include "eval/cloud_render.h"
#include "eval/depth_png.h"

namespace dispmvs::eval {

namespace fs = std::filesystem;
using colmap_io::DenseArray;

void HtmlReportOptions::Check() const {
  if (thumbnail_width < 16 || thumbnail_width > 2048) {
    throw std::invalid_argument("thumbnail width must be in [16, 2048]");
  }
  if (cloud_view_size < 32 || cloud_view_size > 4096) {
    throw std::invalid_argument("cloud view size must be in [32, 4096]");
  }
}

namespace {

// Our maps and PatchMatch's, in the order of the table's columns.
struct MapType {
  const char* type;
  const char* title;
};
constexpr MapType kOurTypes[] = {{"dispmvs.photometric", "dispmvs photometric"},
                                 {"dispmvs.geometric", "dispmvs geometric"}};
constexpr MapType kPatchMatchTypes[] = {{"photometric", "PatchMatch photometric"},
                                        {"geometric", "PatchMatch geometric"}};

std::string Escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Base64(const std::vector<uchar>& bytes) {
  static const char* const kAlphabet =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const uint32_t n = (uint32_t{bytes[i]} << 16) |
                       (i + 1 < bytes.size() ? uint32_t{bytes[i + 1]} << 8 : 0) |
                       (i + 2 < bytes.size() ? uint32_t{bytes[i + 2]} : 0);
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(n >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[n & 63] : '=';
  }
  return out;
}

std::string Percent(double fraction) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f%%", 100.0 * fraction);
  return text;
}

std::string Number(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.4g", value);
  return text;
}

std::string Seconds(double seconds) {
  char text[32];
  std::snprintf(text, sizeof text, "%.2f s", seconds);
  return text;
}

class Page {
 public:
  // An <img> of `image` (BGR) scaled to `width` wide, as a JPEG data URI.
  void Image(const cv::Mat& image, int width, const std::string& alt, bool nearest = false) {
    cv::Mat scaled = image;
    if (image.cols != width) {
      const int height = std::max(1, static_cast<int>(std::lround(
                                         static_cast<double>(image.rows) * width / image.cols)));
      cv::resize(image, scaled, cv::Size(width, height), 0, 0,
                 nearest ? cv::INTER_NEAREST : cv::INTER_AREA);
    }
    std::vector<uchar> jpeg;
    cv::imencode(".jpg", scaled, jpeg, {cv::IMWRITE_JPEG_QUALITY, 85});
    html_ << "<img loading=\"lazy\" width=\"" << scaled.cols << "\" height=\"" << scaled.rows
          << "\" alt=\"" << Escape(alt) << "\" src=\"data:image/jpeg;base64," << Base64(jpeg)
          << "\">";
    ++images_;
  }
  std::ostringstream& html() { return html_; }
  int images() const { return images_; }

 private:
  std::ostringstream html_;
  int images_ = 0;
};

double ValidFraction(const DenseArray& depth) {
  std::size_t valid = 0;
  for (float d : depth.values()) valid += std::isfinite(d) && d > 0 ? 1 : 0;
  return depth.size() == 0 ? 0 : static_cast<double>(valid) / static_cast<double>(depth.size());
}

// Normals in the camera frame -> RGB ((n + 1) / 2), 0 (unknown) black.
cv::Mat ColouriseNormals(const DenseArray& normals) {
  cv::Mat out(normals.height(), normals.width(), CV_8UC3, cv::Scalar::all(0));
  for (int row = 0; row < normals.height(); ++row) {
    for (int col = 0; col < normals.width(); ++col) {
      const float x = normals.at(row, col, 0), y = normals.at(row, col, 1),
                  z = normals.at(row, col, 2);
      if (!(std::isfinite(x) && std::isfinite(y) && std::isfinite(z)) || x * x + y * y + z * z < 1e-6f) {
        continue;
      }
      auto channel = [](float v) {
        return static_cast<uchar>(std::clamp(127.5f * (v + 1.0f), 0.0f, 255.0f));
      };
      out.at<cv::Vec3b>(row, col) = cv::Vec3b(channel(z), channel(y), channel(x));
    }
  }
  return out;
}

cv::Mat Greyscale(const DenseArray& values) {
  cv::Mat out(values.height(), values.width(), CV_8UC3);
  for (int row = 0; row < values.height(); ++row) {
    for (int col = 0; col < values.width(); ++col) {
      const float v = values.at(row, col);
      const auto g = static_cast<uchar>(std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) * 255.0f : 0);
      out.at<cv::Vec3b>(row, col) = cv::Vec3b(g, g, g);
    }
  }
  return out;
}

// The view's colour scale: the 2nd to 98th percentile of the valid depths,
// so that a few wild pixels do not squeeze the rest into one colour.
std::optional<DepthRange> RobustRange(const DenseArray& depth) {
  std::vector<float> valid;
  for (float d : depth.values()) {
    if (std::isfinite(d) && d > 0) valid.push_back(d);
  }
  if (valid.empty()) return std::nullopt;
  auto at = [&valid](double q) {
    const auto k = static_cast<std::size_t>(q * static_cast<double>(valid.size() - 1));
    std::nth_element(valid.begin(), valid.begin() + static_cast<std::ptrdiff_t>(k), valid.end());
    return static_cast<double>(valid[k]);
  };
  DepthRange range;
  range.low = at(0.02);
  range.high = std::max(at(0.98), range.low * (1 + 1e-6) + 1e-12);
  return range;
}

// The first of `images` whose camera is a pinhole one (after
// image_undistorter, all are), with its name; nullopt when none is.
std::optional<std::pair<std::string, CloudCamera>> FirstPinholeCamera(
    const colmap_io::SparseModel& model, const std::vector<const colmap_io::Image*>& images) {
  for (const colmap_io::Image* image : images) {
    const colmap_io::Camera& camera = model.cameras.at(image->camera_id);
    if (!camera.IsPinhole()) continue;
    CloudCamera view;
    view.K = camera.CalibrationMatrix();
    view.R = image->RotationMatrix();
    view.t = image->tvec;
    view.width = static_cast<int>(camera.width);
    view.height = static_cast<int>(camera.height);
    return std::make_pair(image->name, view);
  }
  return std::nullopt;
}

void WriteStyle(std::ostringstream& html) {
  html << "<style>body{font-family:sans-serif;background:#fafafa;color:#222;margin:1em}"
          "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px;"
          "vertical-align:top;text-align:center;font-size:12px}th{background:#eee}"
          "td.name{text-align:left;font-weight:bold}img{display:block;margin:auto}"
          "pre{background:#eee;padding:6px;white-space:pre-wrap}.bar{font-size:11px}"
          "</style>\n";
}

}  // namespace

HtmlReportSummary WriteHtmlReport(const fs::path& workspace_path, const fs::path& html_path,
                                  const HtmlReportOptions& options) {
  options.Check();
  const colmap_io::Workspace workspace(workspace_path);
  const colmap_io::SparseModel model = workspace.ReadModel();
  std::vector<const colmap_io::Image*> images;
  for (const auto& [id, image] : model.images) images.push_back(&image);
  std::sort(images.begin(), images.end(),
            [](const auto* a, const auto* b) { return a->name < b->name; });
  bool any_patchmatch = false;
  for (const auto* image : images) {
    for (const MapType& type : kPatchMatchTypes) {
      any_patchmatch = any_patchmatch || fs::is_regular_file(workspace.DepthMapPath(image->name, type.type));
    }
  }

  Page page;
  std::ostringstream& html = page.html();
  html << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
       << "<title>dispmvs report: " << Escape(workspace_path.string()) << "</title>\n";
  WriteStyle(html);
  html << "</head><body>\n<h1>dispmvs report</h1>\n<p>Workspace: <code>"
       << Escape(fs::absolute(workspace_path).string()) << "</code>, " << images.size()
       << " registered image(s).</p>\n";

  // The fused cloud.
  const fs::path ply = options.ply_path.empty() ? workspace.root() / "fused.ply" : fs::path(options.ply_path);
  html << "<h2>Fused point cloud</h2>\n";
  if (fs::is_regular_file(ply)) {
    const std::vector<colmap_io::PlyPoint> points = colmap_io::ReadPlyPoints(ply);
    html << "<p><code>" << Escape(ply.string()) << "</code>: " << points.size()
         << " points. Orthographic views along the principal axes of its dense part (far "
            "points, such as sky or stray matches, left out of the frame), and the view from "
            "the first image's camera:</p>\n<table><tr>";
    const char* titles[] = {"top (thinnest axis)", "front", "side"};
    const std::vector<cv::Mat> views = RenderCloudViews(points, options.cloud_view_size);
    for (int v = 0; v < 3; ++v) {
      html << "<td>" << titles[v];
      page.Image(views[static_cast<std::size_t>(v)], options.cloud_view_size, titles[v]);
      html << "</td>";
    }
    html << "</tr></table>\n";
    if (const auto first = FirstPinholeCamera(model, images)) {
      const std::string title = "from the camera of " + first->first;
      html << "<p>" << Escape(title) << "</p>\n";
      page.Image(RenderCloudFromCamera(points, first->second, 2 * options.cloud_view_size),
                 2 * options.cloud_view_size, title);
    }
  } else {
    html << "<p>No fused cloud at <code>" << Escape(ply.string()) << "</code>.</p>\n";
  }
  if (!options.settings.empty()) {
    html << "<h2>Settings</h2>\n<pre>" << Escape(options.settings) << "</pre>\n";
  }

  // Time of the photometric pass, from the views' records.
  std::vector<std::optional<colmap_io::ViewRecord>> records;
  int timed = 0;
  double total_seconds = 0;
  const colmap_io::Image* slowest = nullptr;
  double slowest_seconds = -1;
  for (const auto* image : images) {
    records.push_back(colmap_io::ReadViewRecord(colmap_io::ViewRecordPath(workspace, image->name)));
    if (!records.back() || !records.back()->failure.empty()) continue;  // failed: no time
    ++timed;
    total_seconds += records.back()->seconds;
    if (records.back()->seconds > slowest_seconds) {
      slowest_seconds = records.back()->seconds;
      slowest = image;
    }
  }
  html << "<h2>Time</h2>\n<p>";
  if (timed > 0) {
    html << "Photometric pass (the network, per view: reading its images, estimating, "
            "writing its maps): "
         << timed << " view(s), " << Seconds(total_seconds) << " in all, "
         << Seconds(total_seconds / timed) << " per view on average, slowest "
         << Escape(slowest->name) << " (" << Seconds(slowest_seconds) << ").";
  } else {
    html << "No view has a recorded time (WS/stereo/dispmvs_records/).";
  }
  html << "</p>\n";

  // One row per image.
  html << "<h2>Depth maps</h2>\n<p>Depth colourised from blue (near) to red (far) on one "
          "scale per view (below the image: the 2nd to 98th percentile of the first map's "
          "depths; beyond it, the end colours); black: no depth. Normals in the "
          "camera frame as RGB; confidence from black (0) to white (1).</p>\n<table><tr>"
          "<th>image</th>";
  for (const MapType& type : kOurTypes) html << "<th>" << type.title << "</th>";
  html << "<th>normals</th><th>confidence</th>";
  if (any_patchmatch) {
    for (const MapType& type : kPatchMatchTypes) html << "<th>" << type.title << "</th>";
  }
  html << "</tr>\n";
  const int width = options.thumbnail_width;
  int without_maps = 0;
  for (std::size_t i = 0; i < images.size(); ++i) {
    const colmap_io::Image* image = images[i];
    std::vector<std::optional<DenseArray>> ours, theirs;
    for (const MapType& type : kOurTypes) ours.push_back(colmap_io::ReadDenseArrayIfPresent(workspace.DepthMapPath(image->name, type.type)));
    for (const MapType& type : kPatchMatchTypes) theirs.push_back(colmap_io::ReadDenseArrayIfPresent(workspace.DepthMapPath(image->name, type.type)));
    bool any_map = false;
    for (const auto* maps : {&ours, &theirs}) {
      for (const auto& map : *maps) any_map = any_map || map.has_value();
    }
    if (!any_map) {  // e.g. a source that is no reference: nothing to show
      ++without_maps;
      continue;
    }
    // The view's colour scale: our photometric map's, else the first map's.
    std::optional<DepthRange> range;
    for (const auto* maps : {&ours, &theirs}) {
      for (const auto& map : *maps) {
        if (!range && map) range = RobustRange(*map);
      }
    }
    html << "<tr><td class=\"name\">" << Escape(image->name);
    // Through the project's reader (its size checked against the camera's
    // before decoding, only the accepted formats decoded): a damaged file
    // must not end the report, nor the run that writes it.
    cv::Mat picture;
    try {
      const fs::path image_path = workspace.ImagePath(image->name);
      cv::Mat rgb;
      colmap_io::ReadImageRgb(image_path, colmap_io::ImageLimitsForCamera(
                                              image_path, model.cameras.at(image->camera_id)))
          .convertTo(rgb, CV_8UC3, 255.0);
      cv::cvtColor(rgb, picture, cv::COLOR_RGB2BGR);
    } catch (const colmap_io::IoError&) {
      // Shown as unreadable below; the run's own log says why.
    }
    if (!picture.empty()) {
      page.Image(picture, width, image->name);
    } else {
      html << "<br>(image unreadable)";
    }
    if (const auto& record = records[i]; record && !record->failure.empty()) {
      html << "<div class=\"bar\">FAILED: " << Escape(record->failure) << "</div>";
    } else if (record) {
      html << "<div class=\"bar\">" << Seconds(record->seconds) << ", " << record->num_sources
           << " source(s), " << Escape(record->device) << "</div>";
    }
    if (range) {
      cv::Mat bar(1, 256, CV_8UC1);
      for (int i = 0; i < 256; ++i) bar.at<uchar>(0, i) = static_cast<uchar>(i);
      cv::Mat coloured;
      cv::applyColorMap(bar, coloured, cv::COLORMAP_TURBO);
      cv::resize(coloured, coloured, cv::Size(width, 10), 0, 0, cv::INTER_NEAREST);
      page.Image(coloured, width, "colour bar");
      html << "<div class=\"bar\">" << Number(range->low) << " &ndash; " << Number(range->high)
           << "</div>";
    }
    html << "</td>";
    auto depth_cell = [&](const std::optional<DenseArray>& map, const char* title) {
      html << "<td>";
      if (map) {
        page.Image(ColouriseDepth(*map, range.value_or(DepthRange{})), width, std::string(title) + " depth", true);
        html << map->width() << "x" << map->height() << ", " << Percent(ValidFraction(*map));
      } else {
        html << "&ndash;";
      }
      html << "</td>";
    };
    for (std::size_t t = 0; t < ours.size(); ++t) depth_cell(ours[t], kOurTypes[t].title);
    // Normals and confidence of our most filtered map.
    const char* ours_type = ours[1] ? kOurTypes[1].type : kOurTypes[0].type;
    const auto normals = colmap_io::ReadDenseArrayIfPresent(workspace.NormalMapPath(image->name, ours_type));
    const auto confidence = colmap_io::ReadDenseArrayIfPresent(workspace.ConfidenceMapPath(image->name, ours_type));
    html << "<td>";
    if (normals && normals->channels() == 3) {
      page.Image(ColouriseNormals(*normals), width, "normals", true);
    } else {
      html << "&ndash;";
    }
    html << "</td><td>";
    if (confidence && confidence->channels() == 1) {
      page.Image(Greyscale(*confidence), width, "confidence", true);
    } else {
      html << "&ndash;";
    }
    html << "</td>";
    if (any_patchmatch) {
      for (std::size_t t = 0; t < theirs.size(); ++t) depth_cell(theirs[t], kPatchMatchTypes[t].title);
    }
    html << "</tr>\n";
  }
  html << "</table>\n";
  if (without_maps > 0) {
    html << "<p>" << without_maps << " registered image(s) without any depth map are not "
         << "listed.</p>\n";
  }
  html << "</body></html>\n";

  const std::string text = html.str();
  colmap_io::WriteFileAtomically(html_path, [&](std::ostream& out) { out << text; });
  HtmlReportSummary summary;
  summary.views = static_cast<int>(images.size());
  summary.embedded_images = page.images();
  summary.bytes = text.size();
  return summary;
}

}  // namespace dispmvs::eval
