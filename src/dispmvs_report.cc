// dispmvs_report: the run report of a dense workspace as one self-contained
// HTML file (eval/html_report.h): what dispmvs_colmap writes at the end of a
// run, for a workspace that exists already (e.g. after PatchMatch, to see
// both side by side).

#include <boost/program_options.hpp>

#include <iostream>
#include <optional>
#include <string>

#include "eval/html_report.h"
#include "src/program_main.h"
#include "src/program_options.h"

namespace {

namespace po = boost::program_options;
using namespace dispmvs;

constexpr const char* kDescription = R"(dispmvs_report: look at a dense workspace in a browser.

Usage: dispmvs_report --workspace_path WS [--output PATH] [options]

Writes one self-contained HTML file (default WS/dispmvs_report.html; images
embedded, no script, nothing fetched): per registered image, the image, our
photometric and geometric depth maps (NAME.dispmvs.*.bin) colourised on one
scale per view with its colour bar and range, normals, confidence and each
map's coverage, and PatchMatch's maps (NAME.photometric.bin,
NAME.geometric.bin) beside them when present; the fused cloud's size and
three pictures of it.

Options)";

struct Options {
  std::string workspace_path;
  std::string output;
  eval::HtmlReportOptions report;
};

std::optional<Options> ParseCommandLine(int argc, char** argv) {
  Options o;
  po::options_description description(kDescription);
  // clang-format off
  description.add_options()
      ("help,h", "Print this help and exit.")
      ("workspace_path", po::value<std::string>(&o.workspace_path),
       "COLMAP dense workspace (required).")
      ("output", po::value<std::string>(&o.output), "HTML file; default WS/dispmvs_report.html.")
      ("ply", po::value<std::string>(&o.report.ply_path),
       "Point cloud to show; default WS/fused.ply (left out when absent).")
      ("thumbnail_width", po::value<int>(&o.report.thumbnail_width)
           ->default_value(o.report.thumbnail_width),
       "Width of the per-view pictures, pixels.");
  // clang-format on
  po::variables_map values;
  if (!cli::ParseCommandLine(argc, argv, description, &values)) return std::nullopt;
  if (o.workspace_path.empty()) {
    throw std::invalid_argument("--workspace_path is required (see --help)");
  }
  if (o.output.empty()) o.output = o.workspace_path + "/dispmvs_report.html";
  o.report.Check();
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&] {
    const std::optional<Options> options = ParseCommandLine(argc, argv);
    if (!options) return 0;
    const dispmvs::eval::HtmlReportSummary summary =
        dispmvs::eval::WriteHtmlReport(options->workspace_path, options->output, options->report);
    std::cout << "report: " << options->output << " (" << summary.views << " image(s), "
              << summary.embedded_images << " pictures, " << summary.bytes / 1024 << " KB)\n";
    return 0;
  });
}
