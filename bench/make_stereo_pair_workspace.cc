// dispmvs_stereo_pair_workspace: a rectified stereo pair with ground-truth
// disparity (e.g. Middlebury 2014) -> a COLMAP dense workspace with ground
// truth, for a real two-view check of dispmvs_colmap with dispmvs_eval (see
// bench/motorcycle_check.sh). Errors print one line "error: <message>" on
// stderr with exit status 1.

#include <boost/program_options.hpp>

#include <cmath>
#include <exception>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <string>

#include "bench/npy_reader.h"
#include "bench/stereo_pair_workspace.h"
#include "src/program_main.h"
#include "src/program_options.h"

namespace {

namespace po = boost::program_options;
using namespace dispmvs;

constexpr const char* kDescription = R"(dispmvs_stereo_pair_workspace: a rectified stereo pair with ground-truth
disparity as a COLMAP dense workspace with ground truth.

Usage: dispmvs_stereo_pair_workspace --left L.png --right R.png --disparity D.npy
           --focal F --cx CX --cy CY --doffs DOFFS --baseline B --output_path WS
           [--num_sparse_points N] [--max_disparity_step S]

Inputs (Middlebury 2014 conventions): two rectified images of one size; the
left image's disparity as a 2-D NumPy .npy file ('<f4' or '<f8', C order,
rows x cols = the image's height x width; +inf, NaN or d + doffs <= 0 =
unknown), where the left pixel x matches the right pixel x - d; the
calibration f, cx, cy (left camera), doffs (right cx = cx + doffs) and the
baseline. Depth is z = baseline * f / (d + doffs), in the baseline's unit
(e.g. mm). cx and cy are taken in COLMAP's convention (top-left pixel centre
at (0.5, 0.5)); a principal point off by the same amount in both cameras
does not change the depths of a rectified pair.

E.g. Middlebury 2014 Motorcycle at quarter size (scikit-image's
motorcycle_*.png and motorcycle_disp.npz's arr_0.npy):
  --focal 994.978 --cx 311.193 --cy 254.877 --doffs 31.086 --baseline 193.001

Output WS (files of the same name are replaced; each written atomically):
  WS/images/left.EXT, right.EXT    the input images, byte for byte
  WS/sparse/                       two PINHOLE cameras (f, f, cx, cy) and
                                   (f, f, cx + doffs, cy); left at the origin,
                                   right with centre (baseline, 0, 0),
                                   identity rotations; sparse points
  WS/stereo/patch-match.cfg        each image with the other as its source
  WS/stereo/fusion.cfg             both images
  WS/ground_truth/depth_maps/left.EXT.bin   GT depth (COLMAP dense array)
  WS/ground_truth/README.txt       calibration, conventions, counts

The sparse points play the part of SfM points: dispmvs_colmap derives its
depth-range hint from them, as it would from a reconstruction. Each is a left
pixel centre with valid disparity, placed at its GT depth and observed in both
images at its exact projections; pixels landing outside the right image or
occluded there (another pixel with a disparity larger by more than
--max_disparity_step lands on the same right pixel) are skipped, and
--num_sparse_points of the rest are taken evenly spaced in raster order.

The GT depth map is in COLMAP's dense indexing (pixel (col, row) = image
position (col, row), the corner between four left pixel centres, as
dispmvs_colmap's maps and COLMAP's PatchMatch use): the depth of the mean of
the four disparities around it, where all four are valid and differ by at
most --max_disparity_step (else it straddles a depth edge: no GT); the first
row and column have none. Score maps with
  dispmvs_eval --workspace_path WS --types dispmvs.photometric
which also reports disparity errors, this being a rectified pair.

Options)";

struct Options {
  std::string left, right, disparity, output_path;
  bench::StereoPairWorkspaceOptions workspace;
};

double RequiredNumber(const po::variables_map& values, const char* name) {
  if (values.count(name) == 0) {
    throw std::invalid_argument(std::string("--") + name + " is required (see --help)");
  }
  const double value = values[name].as<double>();
  if (!std::isfinite(value)) throw std::invalid_argument(std::string("--") + name + " must be finite");
  return value;
}

std::string RequiredPath(const po::variables_map& values, const char* name) {
  if (values.count(name) == 0 || values[name].as<std::string>().empty()) {
    throw std::invalid_argument(std::string("--") + name + " is required (see --help)");
  }
  return values[name].as<std::string>();
}

std::optional<Options> ParseCommandLine(int argc, char** argv) {
  Options o;
  po::options_description description(kDescription);
  // clang-format off
  description.add_options()
      ("help,h", "Print this help and exit.")
      ("left", po::value<std::string>(), "Left image (required).")
      ("right", po::value<std::string>(), "Right image, same size (required).")
      ("disparity", po::value<std::string>(),
       "The left image's disparity, a 2-D .npy file ('<f4' or '<f8', C order) (required).")
      ("focal", po::value<double>(), "Focal length in pixels, both cameras (required).")
      ("cx", po::value<double>(), "Left principal point x, pixels (required).")
      ("cy", po::value<double>(), "Principal point y, pixels, both cameras (required).")
      ("doffs", po::value<double>(), "Right cx minus left cx, pixels (required).")
      ("baseline", po::value<double>(),
       "Distance of the camera centres; its unit is the workspace's (required).")
      ("output_path", po::value<std::string>(), "Workspace folder to write (required).")
      ("num_sparse_points", po::value<int>(&o.workspace.num_sparse_points)->default_value(2000),
       "Sparse points (two-view tracks) for the depth-range hint.")
      ("max_disparity_step",
       po::value<double>(&o.workspace.max_disparity_step)->default_value(1.0, "1"),
       "Disparity difference (pixels) taken as a depth edge: GT corners across one are left "
       "empty, and a sparse point is occluded by a pixel this much nearer.");
  // clang-format on

  po::variables_map values;
  if (!cli::ParseCommandLine(argc, argv, description, &values)) return std::nullopt;
  o.left = RequiredPath(values, "left");
  o.right = RequiredPath(values, "right");
  o.disparity = RequiredPath(values, "disparity");
  o.output_path = RequiredPath(values, "output_path");
  bench::StereoPairCalibration& c = o.workspace.calibration;
  c.focal = RequiredNumber(values, "focal");
  c.cx = RequiredNumber(values, "cx");
  c.cy = RequiredNumber(values, "cy");
  c.doffs = RequiredNumber(values, "doffs");
  c.baseline = RequiredNumber(values, "baseline");
  if (!(c.focal > 0)) throw std::invalid_argument("--focal must be > 0");
  if (!(c.baseline > 0)) throw std::invalid_argument("--baseline must be > 0");
  if (o.workspace.num_sparse_points < 1 || o.workspace.num_sparse_points > 10000000) {
    throw std::invalid_argument("--num_sparse_points must be in [1, 10000000]");
  }
  if (!(o.workspace.max_disparity_step > 0)) {
    throw std::invalid_argument("--max_disparity_step must be > 0");
  }
  o.workspace.left_image = o.left;
  o.workspace.right_image = o.right;
  o.workspace.Check();
  return o;
}

int Run(const Options& options) {
  const bench::NpyMatrix disparity = bench::ReadNpyMatrix(options.disparity);
  const bench::StereoPairWorkspaceSummary summary = bench::WriteStereoPairWorkspace(
      options.output_path, disparity, options.disparity, options.workspace);
  const double pixels = static_cast<double>(summary.width) * summary.height;
  std::cout << "workspace: " << options.output_path << '\n'
            << "images: " << summary.left_name << ", " << summary.right_name << " ("
            << summary.width << "x" << summary.height << ")\n"
            << "disparity: " << summary.valid_disparities << " valid of "
            << static_cast<int64_t>(pixels) << " (" << disparity.descr << ")\n"
            << "ground truth: " << summary.gt_pixels << " pixels with depth ("
            << 100.0 * summary.gt_pixels / pixels << "%), " << summary.gt_dropped_at_edges
            << " dropped at depth edges, depth " << summary.gt_min_depth << " to "
            << summary.gt_max_depth << '\n'
            << "sparse points: " << summary.num_points3D << " (of " << summary.sparse_candidates
            << " candidates)\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&] {
    const std::optional<Options> options = ParseCommandLine(argc, argv);
    return options ? Run(*options) : 0;
  });
}
