// dispmvs_make_example: writes the example COLMAP dense workspace (a synthetic
// scene with exact geometry and ground-truth depth; see example_workspace.h).
//
//   dispmvs_make_example --output_path DIR [--seed S]
//                        [--ground_truth_sampling pixel-centres|colmap-dense]

#include <cstdint>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <string>

#include "examples/example_workspace.h"

namespace {

constexpr const char* kUsage =
    "Usage: dispmvs_make_example --output_path DIR [--seed S]\n"
    "                            [--ground_truth_sampling pixel-centres|colmap-dense]\n"
    "Writes a COLMAP dense workspace of a synthetic scene (textured ground and box,\n"
    "7 PINHOLE views of 320x240, sparse model, patch-match.cfg with __auto__, 4)\n"
    "with exact ground-truth depth and normal maps under DIR/ground_truth/.\n"
    "The output is a deterministic function of S (default 0).\n"
    "Ground-truth pixel (col, row) holds the ray through (col + 0.5, row + 0.5)\n"
    "(pixel-centres, the default) or through (col, row) (colmap-dense: how\n"
    "COLMAP's PatchMatch and stereo_fusion index their depth maps).\n";

bool ParseSeed(const std::string& text, uint64_t* seed) {
  if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos) return false;
  try {
    *seed = std::stoull(text);
  } catch (const std::exception&) {
    return false;  // out of range
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::string output_path;
  dispmvs::examples::ExampleWorkspaceOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::cout << kUsage;
      return EXIT_SUCCESS;
    }
    const bool takes_value =
        arg == "--output_path" || arg == "--seed" || arg == "--ground_truth_sampling";
    if (takes_value && i + 1 < argc) {
      const std::string value = argv[++i];
      if (arg == "--output_path") {
        output_path = value;
      } else if (arg == "--seed") {
        if (!ParseSeed(value, &options.seed)) {
          std::cerr << "dispmvs_make_example: --seed must be a non-negative integer, got '"
                    << value << "'\n";
          return EXIT_FAILURE;
        }
      } else if (value == "pixel-centres") {
        options.sampling = dispmvs::examples::GroundTruthSampling::kPixelCentres;
      } else if (value == "colmap-dense") {
        options.sampling = dispmvs::examples::GroundTruthSampling::kColmapDenseIndexing;
      } else {
        std::cerr << "dispmvs_make_example: --ground_truth_sampling must be pixel-centres or "
                     "colmap-dense, got '"
                  << value << "'\n";
        return EXIT_FAILURE;
      }
      continue;
    }
    std::cerr << "dispmvs_make_example: unexpected argument '" << arg << "'\n" << kUsage;
    return EXIT_FAILURE;
  }
  if (output_path.empty()) {
    std::cerr << "dispmvs_make_example: --output_path is required\n" << kUsage;
    return EXIT_FAILURE;
  }
  try {
    const auto summary = dispmvs::examples::WriteExampleWorkspace(output_path, options);
    std::cout << "Wrote " << output_path << ": " << summary.num_images << " images, "
              << summary.num_points3D << " sparse points, " << summary.num_observations
              << " observations\n";
  } catch (const std::exception& e) {
    std::cerr << "dispmvs_make_example: " << e.what() << "\n";
    return EXIT_FAILURE;
  }
  return EXIT_SUCCESS;
}
