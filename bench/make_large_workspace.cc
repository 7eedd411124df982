// dispmvs_make_large_workspace: a synthetic COLMAP dense workspace of any
// number of images with exact photometric maps, for measuring how planning,
// the geometric filter and fusion scale (bench/scale_bench.sh). Errors print
// one line "error: <message>" on stderr with exit status 1.

#include <boost/program_options.hpp>

#include <cstdint>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <string>

#include "bench/large_workspace.h"
#include "src/program_main.h"
#include "src/program_options.h"

namespace {

namespace po = boost::program_options;
using namespace dispmvs;

constexpr const char* kDescription = R"(dispmvs_make_large_workspace: a large synthetic COLMAP dense workspace with
exact depth maps, for timing `dispmvs_colmap --mode plan` and `--mode fuse`
at thousands of images without running the network.

Usage: dispmvs_make_large_workspace --output_path WS --images N
           [--width W --height H] [--points_per_image P] [--seed S]

Scene: the ground plane z = 0, textured by its world position (every view
sees the same colours there). One PINHOLE camera (focal 0.8 W, principal
point at the centre) flies over it on a grid of 20 images per row at height
10, looking down with a 15 degree forward tilt, so depth changes from row to
row of an image. Neighbours overlap by 70% of a footprint along both axes
(a triangulation angle of about 20 degrees).

Output WS (files of the same names are replaced, each written atomically;
sparse/ last, so an interrupted run leaves no model):
  WS/images/img_00000.png ...      the rendered views
  WS/sparse/*.bin                  camera, poses, sparse points on the plane
                                   observed at their exact projections by
                                   every image whose frame holds them
  WS/stereo/{depth,normal,confidence}_maps/NAME.dispmvs.photometric.bin
                                   exact maps in COLMAP's dense indexing
                                   (pixel (col, row) = the ray K^-1 (col, row, 1)),
                                   plane normals facing the camera, confidence 1
No patch-match.cfg and no fusion.cfg: every image is a reference with
`__auto__` sources. Then, e.g.:
  dispmvs_colmap --workspace_path WS --mode plan
  dispmvs_colmap --workspace_path WS --mode fuse

Options)";

struct Options {
  std::string output_path;
  bench::LargeWorkspaceOptions workspace;
};

std::optional<Options> ParseCommandLine(int argc, char** argv) {
  Options o;
  po::options_description description(kDescription);
  // clang-format off
  description.add_options()
      ("help,h", "Print this help and exit.")
      ("output_path", po::value<std::string>(&o.output_path), "Workspace folder to write (required).")
      ("images", po::value<int>(&o.workspace.num_images), "Number of images, 2 or more (required).")
      ("width", po::value<int>(&o.workspace.width)->default_value(160), "Image width, pixels.")
      ("height", po::value<int>(&o.workspace.height)->default_value(120), "Image height, pixels.")
      ("points_per_image", po::value<int>(&o.workspace.points_per_image)->default_value(100),
       "Sparse points an image observes, about (0: a model without points, so that "
       "dispmvs_colmap chooses sources from the poses).")
      ("seed", po::value<uint64_t>(&o.workspace.seed)->default_value(1),
       "Seed of the texture and the sparse points.");
  // clang-format on
  po::variables_map values;
  if (!cli::ParseCommandLine(argc, argv, description, &values)) return std::nullopt;
  if (o.output_path.empty()) throw std::invalid_argument("--output_path is required (see --help)");
  if (values.count("images") == 0) throw std::invalid_argument("--images is required (see --help)");
  o.workspace.Check();
  return o;
}

int Run(const Options& options) {
  const bench::LargeWorkspaceSummary s =
      bench::WriteLargeWorkspace(options.output_path, options.workspace, std::cout);
  std::cout << "workspace: " << options.output_path << '\n'
            << "images: " << s.num_images << " (" << options.workspace.width << "x"
            << options.workspace.height << ") in " << s.num_rows << " row(s), spacing "
            << s.spacing_x << " x " << s.spacing_y << ", neighbour angles "
            << s.neighbour_angle_x_deg << " / " << s.neighbour_angle_y_deg << " deg\n"
            << "depth: " << s.depth_min << " to " << s.depth_max << '\n'
            << "sparse points: " << s.num_points3D << ", " << s.num_observations
            << " observations (" << static_cast<double>(s.num_observations) / s.num_images
            << " per image)\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&] {
    const std::optional<Options> options = ParseCommandLine(argc, argv);
    return options ? Run(*options) : 0;
  });
}
