// dispmvs_synth: writes generated scenes as COLMAP dense workspaces with exact
// ground truth (synth/workspace_writer.h describes the layout).
//
//   dispmvs_synth --output_path DIR --num_scenes K [--seed S]
//                 [--width 640 --height 512 --num_views 6]
//                 [--rig table|walkthrough|turntable|outdoor|random]
//
// Scenes go to DIR/scene_000, DIR/scene_001, ...; scenes already complete
// from an earlier run are skipped, so an interrupted run can be resumed.

#include <boost/program_options.hpp>

#include <chrono>
#include <cstdint>
#include <exception>
#include <iostream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>

#include "synth/jpeg.h"
#include "synth/photo_folder.h"
#include "synth/shading.h"
#include "synth/workspace_writer.h"
#include "src/program_main.h"
#include "src/program_options.h"

namespace {

namespace po = boost::program_options;

constexpr const char* kDescription =
    "dispmvs_synth: synthetic scenes as COLMAP dense workspaces with ground truth.\n"
    "Usage: dispmvs_synth --output_path DIR --num_scenes K [options]\n\nOptions";

struct Options {
  std::string output_path;
  int num_scenes = 0;
  uint64_t seed = 0;
  std::string rig = "random";
  std::string texture_dir;
  std::string photometry = "default";
  std::string jpeg_quality;
  dispmvs::synth::SynthWorkspaceOptions workspace;
};

std::optional<Options> ParseCommandLine(int argc, char** argv) {
  Options options;
  dispmvs::synth::SynthConfig& config = options.workspace.config;
  config.width = 640;
  config.height = 512;
  config.num_views = 6;
  po::options_description description(kDescription);
  description.add_options()
      ("help,h", "Print this help and exit.")
      ("output_path", po::value<std::string>(&options.output_path),
       "Folder of the data set (required); created if missing.")
      ("num_scenes", po::value<int>(&options.num_scenes), "Number of scenes (required), >= 1.")
      ("seed", po::value<uint64_t>(&options.seed)->default_value(options.seed),
       "Base seed; scene i uses a seed mixed from it and i.")
      ("width", po::value<int64_t>(&config.width)->default_value(config.width), "Image width in pixels.")
      ("height", po::value<int64_t>(&config.height)->default_value(config.height), "Image height in pixels.")
      ("num_views", po::value<int>(&config.num_views)->default_value(config.num_views),
       "Views per scene (reference + sources), >= 2.")
      ("rig", po::value<std::string>(&options.rig)->default_value(options.rig),
       "Camera rig: table, walkthrough, turntable, outdoor, or random (drawn per scene).")
      ("sparse_points_per_view",
       po::value<int>(&options.workspace.sparse_points_per_view)
           ->default_value(options.workspace.sparse_points_per_view),
       "Sparse points drawn per view (before the two-view visibility test).")
      ("texture_dir", po::value<std::string>(&options.texture_dir),
       "Folder of photographs (png, jpg, ...) used as textures besides the procedural ones, "
       "e.g. the photos of Debian's python3-skimage data folder (leave out motorcycle_*: "
       "bench/motorcycle_check.sh evaluates on them).")
      ("photo_probability", po::value<double>(&config.photo_probability)->default_value(config.photo_probability, "0.5"),
       "With --texture_dir: the share of textures that are photos.")
      ("difficulty", po::value<double>(&config.difficulty)->default_value(config.difficulty, "1"),
       "Scene difficulty in [0, 1]: 1 is the full generator; lower values shrink the baselines, "
       "remove occluders, soften the light and narrow the per-view photometry.")
      ("specular_probability",
       po::value<double>(&config.specular_probability)->default_value(config.specular_probability, "0"),
       "Share of the objects and walls with a glossy coat: a white highlight that stands elsewhere "
       "on the surface in every view (strength 0.15-0.6, Blinn-Phong exponent 8-256).")
      ("background_at_infinity", po::bool_switch(&config.background_at_infinity),
       "Draw the outdoor scenes' sky at infinity: no parallax between views, and no depth there "
       "(0 in the ground truth, as for a real sky). Without it the sky is a finite sphere "
       "700-1200 units away, with its depth.")
      ("supersampling", po::value<int>(&config.supersampling)->default_value(config.supersampling),
       "Rays per pixel along each axis (odd, 1 to 7): each pixel's colour is the mean of s x s rays "
       "inside it, as a camera integrates light over the pixel; 1 is one ray through the centre, "
       "which aliases textures finer than a pixel. Depths are the centre ray's either way.")
      ("photometry", po::value<std::string>(&options.photometry)->default_value(options.photometry),
       "Per-view camera response: default, or wide (exposure 0.5-2x, white balance +-15 %, gamma "
       "0.7-1.4 and vignetting up to 0.4 between views, as between real photographs; "
       "dispmvs_train --photometry wide).")
      ("jpeg_quality", po::value<std::string>(&options.jpeg_quality),
       "Save every view as a JPEG of this quality would be, Q or MIN,MAX (1-100, drawn per view): "
       "8-bit samples, 4:2:0 chroma and 8 x 8 block artefacts that differ between views, as in "
       "photographs. The images are still written as PNG. Default: no compression.")
      ("ply_stride", po::value<int>(&options.workspace.ply_stride)->default_value(options.workspace.ply_stride),
       "ground_truth/points.ply keeps every n-th depth sample per row and column.");

  po::variables_map values;
  if (!dispmvs::cli::ParseCommandLine(argc, argv, description, &values)) return std::nullopt;
  if (values.count("output_path") == 0) throw std::invalid_argument("--output_path is required (see --help)");
  if (values.count("num_scenes") == 0) throw std::invalid_argument("--num_scenes is required (see --help)");
  if (options.num_scenes < 1) throw std::invalid_argument("--num_scenes must be >= 1");
  if (options.photometry == "wide") {
    config.photometry = dispmvs::synth::WidePhotometry();
  } else if (options.photometry != "default") {
    throw std::invalid_argument("--photometry must be default or wide, got '" + options.photometry + "'");
  }
  std::tie(config.jpeg_quality_min, config.jpeg_quality_max) =
      dispmvs::synth::ParseJpegQualityRange(options.jpeg_quality);
  config = dispmvs::synth::ConfigForRig(options.rig, config);
  if (!options.texture_dir.empty()) {
    config.photos = std::make_shared<const dispmvs::synth::PhotoSet>(
        dispmvs::synth::LoadPhotoFolder(options.texture_dir, {}, &std::cerr));
    std::cout << config.photos->size() << " photos from " << options.texture_dir << '\n';
  }
  options.workspace.Check();
  return options;
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&] {
    const std::optional<Options> options = ParseCommandLine(argc, argv);
    if (!options) return 0;
    const auto start = std::chrono::steady_clock::now();
    const dispmvs::synth::SynthDatasetSummary summary = dispmvs::synth::WriteSynthDataset(
        options->output_path, options->num_scenes, options->seed, options->workspace, &std::cout);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << summary.written << " scenes written, " << summary.skipped << " skipped, in " << seconds << " s\n";
    return 0;
  });
}
