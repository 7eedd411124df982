// One table of bad inputs to dispmvs_colmap and dispmvs_eval: each case
// breaks a fresh copy of the embedded example (or passes a bad option) and
// pins the exit status, the first line of the message that says what is
// wrong, and what may be written: nothing at all when the input is refused
// before any work, or, when single views fail, nothing for those views and
// only complete files for the others (every written map and cloud parses).
//
// {WS} in an expected line stands for the case's workspace, {DIR} for its
// scratch folder.

#include <sys/resource.h>
#include <unistd.h>

#include <csignal>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model_io.h"
#include "dense/test_workspace.h"
#include "examples/example_workspace.h"
#include "tests/support/run_program.h"
#include "tests/support/temp_dir.h"
#include "tests/support/workspace_outputs.h"

namespace dispmvs {
namespace {

namespace fs = std::filesystem;
using testing::ReadFileBytes;
using testing::TempDir;
using testing::WriteFileBytes;

enum class Program { kColmap, kEval };
enum class Written {
  kNothing,        // no file created or changed anywhere
  kOthersOnly,     // `failed_views` have no maps; every written file is complete
  kAllOthers,      // as kOthersOnly, and every other view has all its maps and
                   // the cloud was fused: one bad file costs its own view only
};

struct BadInputCase {
  std::string name;
  int status = 1;
  std::string first_line;  // of standard error, else the first warning or FAILED line
  Program program = Program::kColmap;
  // Breaks the workspace at ws (the example, seed 1; for kEval with exact
  // maps as dispmvs.photometric and its ground truth).
  std::function<void(const fs::path& ws)> breaks;
  std::string args;  // after --workspace_path WS; {WS} and {DIR} substituted
  Written written = Written::kNothing;
  std::vector<std::string> failed_views = {};
  // > 0: the most bytes any file may have (RLIMIT_FSIZE), a full disk.
  rlim_t file_size_limit = 0;
  bool needs_non_root = false;  // permissions do not stop root
  std::string also_says = "";   // a line of standard output must contain this
};

const std::string kUnknownFormat =
    "not an image in a supported format (PNG, JPEG, TIFF, BMP, PNM, WebP): unknown or damaged "
    "file signature";

// --- ways to break a workspace ------------------------------------------

void Truncate(const fs::path& path, double keep) {
  const std::string bytes = ReadFileBytes(path);
  WriteFileBytes(path, bytes.substr(0, static_cast<std::size_t>(bytes.size() * keep)));
}

void Overwrite(const fs::path& path, const std::string& bytes) { WriteFileBytes(path, bytes); }

// The inputs the image fuzzer found (tests/fuzz/regressions/image_fuzzer).
std::string FuzzFinding(const std::string& name) {
  return ReadFileBytes(fs::path(DISPMVS_SOURCE_DIR) / "tests/fuzz/regressions/image_fuzzer" / name);
}

// `image` re-encoded as `extension` (".jpg", ".tif") under its own name, the
// first `keep` of the file kept: a copy cut short.
void ReencodeTruncated(const fs::path& image, const std::string& extension, double keep) {
  std::vector<uchar> bytes;
  ASSERT_TRUE(cv::imencode(extension, cv::imread(image.string()), bytes));
  WriteFileBytes(image, std::string(bytes.begin(), bytes.begin() + static_cast<long>(bytes.size() * keep)));
}

// The sparse model rewritten as text (what COLMAP's model_converter
// writes), so that single numbers can be edited.
void SparseToText(const fs::path& ws) {
  if (!fs::exists(ws / "sparse" / "cameras.bin")) return;  // done already
  const colmap_io::SparseModel model = colmap_io::ReadSparseModelBinary(ws / "sparse");
  for (const char* file : {"cameras.bin", "images.bin", "points3D.bin"}) fs::remove(ws / "sparse" / file);
  colmap_io::WriteSparseModelText(model, ws / "sparse");
}

// Replaces the `token`-th whitespace-separated token of the `record`-th
// non-comment line of a text model file (images.txt: two lines per image).
void EditText(const fs::path& path, int record, int token, const std::string& value) {
  std::istringstream in(ReadFileBytes(path));
  std::ostringstream out;
  std::string line;
  int index = 0;
  while (std::getline(in, line)) {
    if (!line.empty() && line[0] != '#' && index++ == record) {
      std::istringstream tokens(line);
      std::vector<std::string> parts;
      std::string part;
      while (tokens >> part) parts.push_back(part);
      parts.at(static_cast<std::size_t>(token)) = value;
      line.clear();
      for (const std::string& p : parts) line += (line.empty() ? "" : " ") + p;
    }
    out << line << '\n';
  }
  WriteFileBytes(path, out.str());
}

void EditCamera(const fs::path& ws, int token, const std::string& value) {
  SparseToText(ws);
  EditText(ws / "sparse" / "cameras.txt", 0, token, value);
}

// Image records of images.txt are every other line (the pose line).
void EditImage(const fs::path& ws, int image, int token, const std::string& value) {
  SparseToText(ws);
  EditText(ws / "sparse" / "images.txt", 2 * image, token, value);
}

std::function<void(const fs::path&)> Nothing() {
  return [](const fs::path&) {};
}

std::vector<BadInputCase> Cases() {
  const std::string fast = " --max_image_size 64 --threads 1";
  std::vector<BadInputCase> cases = {
      // Sparse model files.
      {"cameras_bin_truncated", 1,
       "error: {WS}/sparse/cameras.bin: number of cameras is 1 but only 24 bytes remain (at least 48 per entry): wrong count or truncated file",
       Program::kColmap,
       [](const fs::path& ws) { Truncate(ws / "sparse" / "cameras.bin", 0.5); }, fast},
      {"images_bin_truncated", 1,
       "error: {WS}/sparse/images.bin: image #3 (image_id 4): number of points2D is 2482 but only 28406 bytes remain (at least 24 per entry): wrong count or truncated file",
       Program::kColmap,
       [](const fs::path& ws) { Truncate(ws / "sparse" / "images.bin", 0.5); }, fast},
      {"points3D_bin_truncated", 1,
       "error: {WS}/sparse/points3D.bin: point3D #2201 (point3D_id 2202): truncated data: xyz needs 8 bytes but only 4 remain",
       Program::kColmap,
       [](const fs::path& ws) { Truncate(ws / "sparse" / "points3D.bin", 0.7); }, fast},
      {"cameras_bin_garbage", 1,
       "error: {WS}/sparse/cameras.bin: number of cameras is 18446744073709551615 but only 56 bytes remain (at least 48 per entry): wrong count or truncated file",
       Program::kColmap,
       [](const fs::path& ws) { Overwrite(ws / "sparse" / "cameras.bin", std::string(64, '\xff')); },
       fast},
      {"images_bin_empty", 1,
       "error: {WS}/sparse/images.bin: truncated data: number of images needs 8 bytes but only 0 remain",
       Program::kColmap,
       [](const fs::path& ws) { Overwrite(ws / "sparse" / "images.bin", ""); }, fast},
      {"cameras_missing", 1,
       "error: {WS}/sparse: no COLMAP sparse model here: expected cameras, images and points3D as .bin (all three) or .txt (all three)",
       Program::kColmap,
       [](const fs::path& ws) { fs::remove(ws / "sparse" / "cameras.bin"); }, fast},
      {"sparse_folder_missing", 1,
       "error: {WS}/sparse: sparse folder of the workspace does not exist",
       Program::kColmap,
       [](const fs::path& ws) { fs::remove_all(ws / "sparse"); }, fast},
      {"images_folder_missing", 1,
       "error: {WS}/images: images folder of the workspace does not exist",
       Program::kColmap,
       [](const fs::path& ws) { fs::remove_all(ws / "images"); }, fast},
      // Cameras and poses.
      {"camera_zero_focal", 1,
       "error: {WS}/sparse: camera 1 of image \"view_00.png\" has a focal length that is not positive (fx 0.000000, fy 280.000000)",
       Program::kColmap,
       [](const fs::path& ws) { EditCamera(ws, 4, "0"); }, fast},
      {"camera_nan_focal", 1,
       "error: {WS}/sparse/cameras.txt: line 4: camera 1: non-finite camera parameter (NaN or inf)",
       Program::kColmap,
       [](const fs::path& ws) { EditCamera(ws, 4, "nan"); }, fast},
      {"camera_inf_principal_point", 1,
       "error: {WS}/sparse/cameras.txt: line 4: camera 1: non-finite camera parameter (NaN or inf)",
       Program::kColmap,
       [](const fs::path& ws) { EditCamera(ws, 6, "inf"); }, fast},
      {"camera_not_pinhole", 1,
       "error: {WS}/sparse: image \"view_00.png\" does not use a PINHOLE or SIMPLE_PINHOLE camera; dense reconstruction needs the output of `colmap image_undistorter`",
       Program::kColmap,
       [](const fs::path& ws) {
         EditCamera(ws, 1, "SIMPLE_RADIAL");  // f cx cy k: drop one number
         EditText(ws / "sparse" / "cameras.txt", 0, 7, "0.01");
       },
       fast},
      {"camera_zero_width", 1,
       "error: {WS}/sparse/cameras.txt: line 4: camera 1: zero image width or height",
       Program::kColmap,
       [](const fs::path& ws) { EditCamera(ws, 2, "0"); }, fast},
      {"image_nan_rotation", 1,
       "error: {WS}/sparse/images.txt: line 9: image 3: non-finite rotation quaternion (NaN or inf)",
       Program::kColmap,
       [](const fs::path& ws) { EditImage(ws, 2, 1, "nan"); }, fast},
      {"image_zero_quaternion", 1,
       "error: {WS}/sparse/images.txt: line 9: image 3: rotation quaternion cannot be normalised (norm 0.000000)",
       Program::kColmap,
       [](const fs::path& ws) {
         for (int token = 1; token <= 4; ++token) EditImage(ws, 2, token, "0");
       },
       fast},
      {"image_inf_translation", 1,
       "error: {WS}/sparse/images.txt: line 9: image 3: non-finite translation (NaN or inf)",
       Program::kColmap,
       [](const fs::path& ws) { EditImage(ws, 2, 6, "inf"); }, fast},
      {"image_unknown_camera", 1,
       "error: {WS}/sparse: image 3 ('view_02.png') uses camera 99, which cameras does not contain",
       Program::kColmap,
       [](const fs::path& ws) { EditImage(ws, 2, 8, "99"); }, fast},
      {"duplicate_image_names", 1,
       "error: {WS}/sparse: images 2 and 3 have the same name 'view_01.png'",
       Program::kColmap,
       [](const fs::path& ws) { EditImage(ws, 2, 9, "view_01.png"); }, fast},
      {"point_nan_position", 1,
       "error: {WS}/sparse/points3D.txt: line 4: point3D 1: non-finite position (NaN or inf)",
       Program::kColmap,
       [](const fs::path& ws) {
         SparseToText(ws);
         EditText(ws / "sparse" / "points3D.txt", 0, 1, "nan");
       },
       fast},
      {"no_sparse_points_paper_weights", 1,
       "error: no depth-range hint for 7 reference image(s) (view_00.png, view_01.png, view_02.png, view_03.png, view_04.png and 2 more): no image sees sparse points to derive one from, and these weights (init = random, the paper's) draw their initialisation inside it; pass --depth_min and --depth_max (the scene's depth range in the model's units; a rough, wide one is enough), or use model v2 weights (init = match), which need no hint",
       Program::kColmap,
       [](const fs::path& ws) {
         SparseToText(ws);
         std::ostringstream images;  // observations dropped with the points
         std::istringstream in(ReadFileBytes(ws / "sparse" / "images.txt"));
         std::string line;
         int index = 0;
         while (std::getline(in, line)) {
           if (!line.empty() && line[0] != '#' && index++ % 2 == 1) line.clear();
           images << line << '\n';
         }
         WriteFileBytes(ws / "sparse" / "images.txt", images.str());
         WriteFileBytes(ws / "sparse" / "points3D.txt", "");
       },
       fast + " --model_path " + DISPMVS_PAPER_MODEL_PATH},
      // Images.
      {"image_missing", 1,
       "warning: image file missing, not used: view_03.png",
       Program::kColmap,
       [](const fs::path& ws) { fs::remove(ws / "images" / "view_03.png"); }, fast,
       Written::kOthersOnly, {"view_03.png"}},
      {"image_unreadable", 1,
       "photometric: [1/7] view_00.png (4 sources): FAILED: {WS}/images/view_00.png: " + kUnknownFormat,
       Program::kColmap,
       [](const fs::path& ws) { Overwrite(ws / "images" / "view_00.png", "not a PNG"); }, fast,
       Written::kAllOthers, {"view_00.png"}, 0, false,
       "; source view_00.png left out: {WS}/images/view_00.png: " + kUnknownFormat},
      // What made OpenCV hand the file to its DICOM decoder, which aborted
      // the process (the fuzzer's finding).
      {"image_dicom_lookalike", 1,
       "photometric: [4/7] view_03.png (4 sources): FAILED: {WS}/images/view_03.png: " + kUnknownFormat,
       Program::kColmap,
       [](const fs::path& ws) {
         Overwrite(ws / "images" / "view_03.png", FuzzFinding("image-gdcm-abort.bin"));
       },
       fast, Written::kAllOthers, {"view_03.png"}, 0, false,
       "; source view_03.png left out: {WS}/images/view_03.png: " + kUnknownFormat},
      // A 222-byte TIFF whose header made the decoder allocate 1 GB.
      {"image_tiff_header_claims_1gb", 1,
       "photometric: [4/7] view_03.png (4 sources): FAILED: {WS}/images/view_03.png: image is 16392x6 but camera 1 is 320x240 (dense MVS needs the undistorted images)",
       Program::kColmap,
       [](const fs::path& ws) {
         Overwrite(ws / "images" / "view_03.png", FuzzFinding("image-tiff-1gb.bin"));
       },
       fast, Written::kAllOthers, {"view_03.png"}, 0, false,
       "; source view_03.png left out: {WS}/images/view_03.png: image is 16392x6"},
      {"image_jpeg_truncated", 1,
       "photometric: [4/7] view_03.png (4 sources): FAILED: {WS}/images/view_03.png: JPEG file is truncated: it ends before its end-of-image marker",
       Program::kColmap,
       [](const fs::path& ws) { ReencodeTruncated(ws / "images" / "view_03.png", ".jpg", 0.6); },
       fast, Written::kAllOthers, {"view_03.png"}},
      {"image_tiff_truncated", 1,
       "photometric: [4/7] view_03.png (4 sources): FAILED: {WS}/images/view_03.png: TIFF file is damaged or truncated: Can not read TIFF directory count",
       Program::kColmap,
       [](const fs::path& ws) { ReencodeTruncated(ws / "images" / "view_03.png", ".tif", 0.6); },
       fast, Written::kAllOthers, {"view_03.png"}},
      {"image_size_disagrees_with_camera", 1,
       "photometric: [1/7] view_00.png (4 sources): FAILED: {WS}/images/view_00.png: image is 160x120 but camera 1 is 320x240 (dense MVS needs the undistorted images)",
       Program::kColmap,
       [](const fs::path& ws) {
         const fs::path image = ws / "images" / "view_00.png";
         cv::Mat resized;
         cv::resize(cv::imread(image.string()), resized, cv::Size(160, 120));
         cv::imwrite(image.string(), resized);
       },
       fast, Written::kAllOthers, {"view_00.png"}},
      // Configurations.
      {"patch_match_cfg_empty", 1,
       "error: {WS}/stereo/patch-match.cfg: names no reference image (an empty file?): list the references and their sources, or delete it to reconstruct every image with `__auto__` sources",
       Program::kColmap,
       [](const fs::path& ws) { Overwrite(ws / "stereo" / "patch-match.cfg", ""); }, fast},
      {"patch_match_cfg_self_reference", 1,
       "error: {WS}/stereo/patch-match.cfg: line 2: \"view_00.png\" lists itself as a source image",
       Program::kColmap,
       [](const fs::path& ws) {
         Overwrite(ws / "stereo" / "patch-match.cfg", "view_00.png\nview_00.png, view_01.png\n");
       },
       fast},
      {"patch_match_cfg_unknown_image", 1,
       "error: {WS}/stereo/patch-match.cfg: source image \"nope.png\" of \"view_00.png\" is not an image of the sparse model",
       Program::kColmap,
       [](const fs::path& ws) {
         Overwrite(ws / "stereo" / "patch-match.cfg", "view_00.png\nnope.png\n");
       },
       fast},
      {"patch_match_cfg_bad_auto", 1,
       "error: {WS}/stereo/patch-match.cfg: line 2: \"x\" is not a number of images (expected \"__auto__, N\" with N a positive integer)",
       Program::kColmap,
       [](const fs::path& ws) {
         Overwrite(ws / "stereo" / "patch-match.cfg", "view_00.png\n__auto__, x\n");
       },
       fast},
      {"fusion_cfg_unknown_image", 1,
       "error: {WS}/stereo/fusion.cfg: image \"nope.png\" is not in the sparse model",
       Program::kColmap,
       [](const fs::path& ws) { Overwrite(ws / "stereo" / "fusion.cfg", "view_00.png\nnope.png\n"); },
       fast},
      // Options.
      {"model_missing", 1,
       "error: cannot use the weights {DIR}/none.safetensors: safetensors {DIR}/none.safetensors: cannot open for reading (no such file)",
       Program::kColmap, Nothing(), fast + " --model_path {DIR}/none.safetensors"},
      {"model_truncated", 1,
       "error: cannot use the weights {DIR}/cut.safetensors: safetensors {DIR}/cut.safetensors: tensor 'context_encoder.net.down16.first.conv.weight': data_offsets [3318596, 3429188] outside the data section of {HALF_MODEL_DATA_BYTES} bytes",
       Program::kColmap,
       [](const fs::path& ws) {
         fs::copy_file(DISPMVS_MODEL_PATH, ws.parent_path() / "cut.safetensors");
         Truncate(ws.parent_path() / "cut.safetensors", 0.5);
       },
       fast + " --model_path {DIR}/cut.safetensors"},
      {"model_garbage", 1,
       "error: cannot use the weights {DIR}/g.safetensors: safetensors {DIR}/g.safetensors: file too short for the header length",
       Program::kColmap,
       [](const fs::path& ws) { WriteFileBytes(ws.parent_path() / "g.safetensors", "{}{}{}"); },
       fast + " --model_path {DIR}/g.safetensors"},
      {"depth_range_inverted", 1,
       "error: --depth_min must be smaller than --depth_max",
       Program::kColmap, Nothing(), fast + " --depth_min 5 --depth_max 1"},
      {"depth_min_nan", 1,
       "error: --depth_min must be a finite number",
       Program::kColmap, Nothing(), fast + " --depth_min nan --depth_max 1"},
      {"max_image_size_zero", 1,
       "error: --max_image_size must be positive, or -1 for full size",
       Program::kColmap, Nothing(), " --max_image_size 0"},
      {"feature_cache_negative", 1,
       "error: --feature_cache_mb must be >= 0",
       Program::kColmap, Nothing(), fast + " --feature_cache_mb -1"},
      {"tensor_cache_negative", 1,
       "error: --tensor_cache_mb must be >= 0",
       Program::kColmap, Nothing(), fast + " --tensor_cache_mb -1"},
      {"filter_min_support_above_one", 1, "error: --filter_min_support must be in [0, 1]",
       Program::kColmap, Nothing(), fast + " --filter_min_support 1.5"},
      {"filter_support_radius_zero", 1, "error: --filter_support_radius must be in [1, 32]",
       Program::kColmap, Nothing(), fast + " --filter_support_radius 0"},
      {"filter_max_reproj_error_zero", 1,
       "error: --filter_max_reproj_error must be a positive number of pixels", Program::kColmap,
       Nothing(), fast + " --filter_max_reproj_error 0"},
      {"band_megapixels_negative", 1,
       "error: --band_megapixels must be a number >= 0 (0 = never in bands)",
       Program::kColmap, Nothing(), fast + " --band_megapixels -2"},
      {"refinement_unknown", 1,
       "error: --refinement must be ncc or none, got 'sgm'",
       Program::kColmap, Nothing(), fast + " --refinement sgm"},
      {"refine_steps_zero", 1,
       "error: --refine_* options: photometric refinement: steps must be in [1, 64]",
       Program::kColmap, Nothing(), fast + " --refine_steps 0"},
      {"refine_propagation_rounds_negative", 1,
       "error: --refine_* options: photometric refinement: propagation_rounds must be in [0, 16]",
       Program::kColmap, Nothing(), fast + " --refine_propagation_rounds -1"},
      {"refine_full_resolution_rounds_too_many", 1,
       "error: --refine_* options: photometric refinement: full_resolution_rounds must be in [0, 16]",
       Program::kColmap, Nothing(), fast + " --refine_full_resolution_rounds 17"},
      {"refine_sweep_hypotheses_too_many", 1,
       "error: --refine_* options: photometric refinement: sweep_hypotheses must be in [0, 1024]",
       Program::kColmap, Nothing(), fast + " --refine_sweep_hypotheses 2000"},
      {"refine_trusted_plane_axis_anchors_odd", 1,
       "error: --refine_* options: photometric refinement: trusted_plane_axis_anchors must be 0, 2 or 4",
       Program::kColmap, Nothing(), fast + " --refine_trusted_plane_axis_anchors 3"},
      {"refine_window_shift_beyond_the_window", 1,
       "error: --refine_* options: photometric refinement: window_shift must be in [0, window_radius]",
       Program::kColmap, Nothing(), fast + " --refine_window_shift 4"},
      {"refine_local_plane_max_change_zero", 1,
       "error: --refine_* options: photometric refinement: local_plane_max_change must be in (0, 1]",
       Program::kColmap, Nothing(), fast + " --refine_local_plane_max_change 0"},
      {"refine_sweep_step_pixels_zero", 1,
       "error: --refine_* options: photometric refinement: sweep_step_pixels must be in (0, 64]",
       Program::kColmap, Nothing(), fast + " --refine_sweep_step_pixels 0"},
      {"confidence_unknown", 1,
       "error: --confidence must be model or network, got 'peak'",
       Program::kColmap, Nothing(), fast + " --confidence peak"},
      {"shard_out_of_range", 1,
       "error: --shard must be K/N with 0 <= K < N (e.g. 0/4), got '2/2'",
       Program::kColmap, Nothing(), fast + " --mode photometric --shard 2/2"},
      {"image_list_unknown_image", 1,
       "error: image \"nope.png\" of the image list is not a reference image of the plan",
       Program::kColmap,
       [](const fs::path& ws) { WriteFileBytes(ws.parent_path() / "list.txt", "nope.png\n"); },
       fast + " --mode photometric --image_list {DIR}/list.txt"},
      // COLMAP's fusion options (masks, bounding box, StereoFusion spellings).
      {"mask_folder_missing", 1,
       "error: {DIR}/masks: the mask path is not a folder",
       Program::kColmap, Nothing(), fast + " --mask_path {DIR}/masks"},
      {"bbox_five_numbers", 1,
       "error: {DIR}/bbox.txt: bounding box must be six numbers (min x y z, then max x y z), got 5",
       Program::kColmap,
       [](const fs::path& ws) { WriteFileBytes(ws.parent_path() / "bbox.txt", "0 0 0 1 1\n"); },
       fast + " --bbox_path {DIR}/bbox.txt"},
      {"bbox_min_above_max", 1,
       "error: {DIR}/bbox.txt: bounding box: min y 2.000000 is above max 1.000000",
       Program::kColmap,
       [](const fs::path& ws) { WriteFileBytes(ws.parent_path() / "bbox.txt", "0 2 0\n1 1 1\n"); },
       fast + " --bbox_path {DIR}/bbox.txt"},
      {"bbox_missing", 1,
       "error: {DIR}/none.txt: cannot open the bounding-box file",
       Program::kColmap, Nothing(), fast + " --bbox_path {DIR}/none.txt"},
      {"colmap_spelling_disagrees", 1,
       "error: --max_reproj_error and --StereoFusion.max_reproj_error are the same option with different values: give one",
       Program::kColmap, Nothing(),
       fast + " --max_reproj_error 1 --StereoFusion.max_reproj_error 2"},
      {"filter_colmap_spelling_disagrees", 1,
       "error: --filter_max_reproj_error and --PatchMatchStereo.filter_geom_consistency_max_cost are the same option with different values: give one",
       Program::kColmap, Nothing(),
       fast + " --filter_max_reproj_error 2 --PatchMatchStereo.filter_geom_consistency_max_cost 1"},
      {"min_num_pixels_disagrees", 1,
       "error: --StereoFusion.min_num_pixels 5 means --min_num_consistent 4, but --min_num_consistent 2 was given too",
       Program::kColmap, Nothing(),
       fast + " --StereoFusion.min_num_pixels 5 --min_num_consistent 2"},
      {"max_num_pixels_below_min", 1,
       "error: --max_num_pixels (2) must be at least --min_num_consistent + 1 (3): a point holds the reference pixel and the pixels it must agree with",
       Program::kColmap, Nothing(), fast + " --StereoFusion.max_num_pixels 2"},
      {"max_normal_error_out_of_range", 1,
       "error: --max_normal_error must be in [0, 180] degrees",
       Program::kColmap, Nothing(), fast + " --StereoFusion.max_normal_error 200"},
      {"workspace_format_pmvs", 1,
       "error: --workspace_format: only COLMAP workspaces are read, got 'PMVS'",
       Program::kColmap, Nothing(), fast + " --workspace_format PMVS"},
      // Where the outputs go.
      {"output_folder_is_a_file", 1,
       "error: {WS}/stereo/depth_maps: cannot create directory: Not a directory",
       Program::kColmap,
       [](const fs::path& ws) {
         fs::remove_all(ws / "stereo" / "depth_maps");
         WriteFileBytes(ws / "stereo" / "depth_maps", "x");
       },
       fast},
      {"output_folder_read_only", 1,
       "error: {WS}/stereo/depth_maps: cannot create files in this folder (read-only?)",
       Program::kColmap,
       [](const fs::path& ws) {
         fs::permissions(ws / "stereo" / "depth_maps", fs::perms::owner_write,
                         fs::perm_options::remove);
       },
       fast, Written::kNothing, {}, 0, /*needs_non_root=*/true},
      // What root cannot write either: a map folder that leads into /proc.
      {"output_folder_not_writable", 1,
       "error: {WS}/stereo/normal_maps: cannot create files in this folder (read-only?)",
       Program::kColmap,
       [](const fs::path& ws) {
         fs::remove_all(ws / "stereo" / "normal_maps");
         fs::create_directory_symlink("/proc", ws / "stereo" / "normal_maps");
       },
       fast},
      {"disk_full", 1,
       "photometric: [1/7] view_00.png (4 sources): FAILED: {WS}/stereo/confidence_maps/view_00.png.dispmvs.photometric.bin: write failed (disk full?)",
       Program::kColmap, Nothing(), fast, Written::kOthersOnly,
       {"view_00.png", "view_01.png", "view_02.png", "view_03.png", "view_04.png", "view_05.png",
        "view_06.png"},
       /*file_size_limit=*/8192},
      {"output_path_unwritable", 1,
       "error: /proc/fused.ply: cannot open for writing",
       Program::kColmap, Nothing(),
       fast + " --output_path /proc/fused.ply"},
      // Evaluation.
      {"eval_ground_truth_missing", 1,
       "error: {WS}/ground_truth/depth_maps: no ground truth: expected a depth map NAME.bin per image in this folder",
       Program::kEval,
       [](const fs::path& ws) { fs::remove_all(ws / "ground_truth"); }, ""},
      {"eval_ground_truth_truncated", 1,
       "error: {WS}/ground_truth/depth_maps/view_00.png.bin: truncated: header says 320x240x1 (307200 bytes of float32) but 153595 bytes follow the header",
       Program::kEval,
       [](const fs::path& ws) {
         Truncate(ws / "ground_truth" / "depth_maps" / "view_00.png.bin", 0.5);
       },
       ""},
      {"eval_map_wrong_size", 1,
       "error: {WS}/stereo/depth_maps/view_01.png.dispmvs.photometric.bin: depth map is 7x9 but its ground truth is 320x240: not the same size nor a down-scale of it by one factor",
       Program::kEval,
       [](const fs::path& ws) {
         colmap_io::WriteDenseArray(colmap_io::DenseArray(7, 9, 1, 1.0f),
                                    ws / "stereo" / "depth_maps" /
                                        "view_01.png.dispmvs.photometric.bin");
       },
       ""},
      // A view dispmvs_colmap failed on: evaluation names it and why.
      {"eval_view_failed_in_run", 1,
       "warning: view_03.png has no dispmvs.photometric map: dispmvs_colmap failed on it: {WS}/images/view_03.png: " + kUnknownFormat,
       Program::kEval,
       [](const fs::path& ws) {
         Overwrite(ws / "images" / "view_03.png", FuzzFinding("image-gdcm-abort.bin"));
         fs::remove(ws / "stereo" / "depth_maps" / "view_03.png.dispmvs.photometric.bin");
         TempDir scratch;
         const testing::ProgramRun run = testing::RunProgram(
             scratch, DISPMVS_COLMAP_PROGRAM,
             "--workspace_path '" + ws.string() + "' --mode photometric --max_image_size 64 --threads 1");
         EXPECT_EQ(run.status, 1) << run.out << run.err;
       },
       ""},
      {"eval_ply_missing", 1,
       "error: {DIR}/none.ply: no such file",
       Program::kEval, Nothing(), " --ply {DIR}/none.ply"},
      {"eval_ply_truncated", 1,
       "error: {DIR}/cut.ply: PLY body has 2113 bytes, 100 vertices need more",
       Program::kEval,
       [](const fs::path& ws) {
         std::vector<colmap_io::PlyPoint> points(100);
         colmap_io::WritePlyPoints(points, ws.parent_path() / "cut.ply");
         Truncate(ws.parent_path() / "cut.ply", 0.8);
       },
       " --ply {DIR}/cut.ply"},
      {"eval_json_unwritable", 1,
       "error: /proc/eval.json: cannot open for writing",
       Program::kEval, Nothing(), " --json /proc/eval.json"},
  };
  return cases;
}


// The data section that the shipped weights keep when cut to half their
// size as Truncate cuts them (safetensors: an 8-byte little-endian header
// length, the header, then the data), read from the file itself, so that
// model_truncated's message follows a refitted file's header length.
std::string HalfModelDataBytes() {
  const std::string bytes = ReadFileBytes(DISPMVS_MODEL_PATH);
  uint64_t header = 0;
  for (int i = 7; i >= 0; --i) header = header << 8 | static_cast<unsigned char>(bytes.at(i));
  return std::to_string(static_cast<uint64_t>(static_cast<std::size_t>(bytes.size() * 0.5)) - 8 - header);
}

std::string Substitute(std::string text, const fs::path& ws, const fs::path& dir) {
  for (const auto& [key, value] : {std::pair<std::string, std::string>{"{WS}", ws.string()},
                                   {"{DIR}", dir.string()}}) {
    for (std::size_t at; (at = text.find(key)) != std::string::npos;) text.replace(at, key.size(), value);
  }
  const std::string half = "{HALF_MODEL_DATA_BYTES}";
  if (const std::size_t at = text.find(half); at != std::string::npos) text.replace(at, half.size(), HalfModelDataBytes());
  return text;
}

// What says what went wrong: the first line of standard error (refused
// before any work: the programs' one-line convention), else the first line
// of standard output that reports a failed view or warns.
std::string Message(const testing::ProgramRun& run) {
  if (!run.err.empty()) return run.err.substr(0, run.err.find('\n'));
  std::istringstream out(run.out);
  std::string line;
  while (std::getline(out, line)) {
    if (line.rfind("warning: ", 0) == 0 || line.find("FAILED") != std::string::npos) return line;
  }
  return "";
}

// The paths that differ between two snapshots (files are too big to print).
std::vector<std::string> Changed(const std::map<std::string, std::string>& before,
                                 const std::map<std::string, std::string>& after) {
  std::vector<std::string> changed;
  for (const auto& [path, bytes] : after) {
    const auto old = before.find(path);
    if (old == before.end() || old->second != bytes) changed.push_back(path);
  }
  for (const auto& [path, bytes] : before) {
    if (after.count(path) == 0) changed.push_back(path + " (removed)");
  }
  return changed;
}

// Test names and failure messages show the case's name, not its bytes.
void PrintTo(const BadInputCase& bad, std::ostream* out) { *out << bad.name; }

class BadInputTest : public ::testing::TestWithParam<BadInputCase> {};

TEST_P(BadInputTest, ExitStatusMessageAndNothingPartial) {
  const BadInputCase& bad = GetParam();
  TempDir dir;
  const fs::path ws = dir.path() / "ws";
  if (bad.program == Program::kEval) {
    dense::testing::WriteExampleWithExactMaps(ws);
  } else {
    examples::ExampleWorkspaceOptions example;
    example.seed = 1;
    examples::WriteExampleWorkspace(ws, example);
  }
  bad.breaks(ws);
  const auto before = testing::FinalOutputs(dir.path());
  const std::string program =
      bad.program == Program::kColmap ? DISPMVS_COLMAP_PROGRAM : DISPMVS_EVAL_PROGRAM;
  if (bad.needs_non_root && ::geteuid() == 0) {
    GTEST_SKIP() << "root writes into read-only folders; run as another user to check this case";
  }
  TempDir scratch;
  const std::string args =
      "--workspace_path '" + ws.string() + "'" + Substitute(bad.args, ws, dir.path());
  testing::ProgramRun run;
  if (bad.file_size_limit > 0) {
    // A full disk: writes beyond the limit fail with EFBIG (SIGXFSZ ignored,
    // as the child inherits both).
    rlimit old_limit{};
    ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old_limit), 0);
    const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
    rlimit limit = old_limit;
    limit.rlim_cur = bad.file_size_limit;
    ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &limit), 0);
    run = testing::RunProgram(scratch, program, args);
    ::setrlimit(RLIMIT_FSIZE, &old_limit);
    std::signal(SIGXFSZ, old_handler);
  } else {
    run = testing::RunProgram(scratch, program, args);
  }
  const std::string message = Message(run);
  std::printf("%s: status %d: %s\n", bad.name.c_str(), run.status, message.c_str());
  EXPECT_EQ(run.status, bad.status) << run.out << run.err;
  EXPECT_EQ(message, Substitute(bad.first_line, ws, dir.path())) << run.out << run.err;
  if (!run.err.empty()) {  // the error convention: one line
    EXPECT_EQ(run.err.find('\n'), run.err.size() - 1) << run.err;
  } else if (bad.program == Program::kColmap && run.status == 1) {
    // Views failed: the closing summary line says so, in full.
    EXPECT_NE(run.out.find(" (with failures: exit status 1)\n"), std::string::npos) << run.out;
  }
  if (!bad.also_says.empty()) {
    EXPECT_NE(run.out.find(Substitute(bad.also_says, ws, dir.path())), std::string::npos)
        << run.out;
  }
  const auto after = testing::FinalOutputs(dir.path());
  if (bad.written == Written::kAllOthers) {
    // Every view but the failed ones has all its maps, and the cloud exists.
    for (const auto& entry : fs::directory_iterator(ws / "images")) {
      const std::string view = entry.path().filename().string();
      if (std::find(bad.failed_views.begin(), bad.failed_views.end(), view) !=
          bad.failed_views.end()) {
        continue;
      }
      for (const char* kind : {"depth_maps", "normal_maps", "confidence_maps"}) {
        for (const char* type : {"photometric", "geometric"}) {
          EXPECT_TRUE(fs::is_regular_file(ws / "stereo" / kind /
                                          (view + ".dispmvs." + type + ".bin")))
              << view << " " << kind << " " << type;
        }
      }
    }
    EXPECT_TRUE(fs::is_regular_file(ws / "fused.ply"));
  }
  if (bad.written == Written::kNothing) {
    EXPECT_EQ(Changed(before, after), std::vector<std::string>{});
    return;
  }
  for (const auto& [relative, bytes] : after) {
    const fs::path path = dir.path() / relative;
    for (const std::string& view : bad.failed_views) {
      EXPECT_EQ(relative.find(view + ".dispmvs"), std::string::npos) << relative;
    }
    if (path.extension() == ".bin" && relative.find("stereo") != std::string::npos) {
      EXPECT_NO_THROW(colmap_io::ReadDenseArray(path)) << relative;
    }
    if (path.filename() == "fused.ply") {
      EXPECT_NO_THROW(colmap_io::ReadPlyPoints(path));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Matrix, BadInputTest, ::testing::ValuesIn(Cases()),
                         [](const ::testing::TestParamInfo<BadInputCase>& info) {
                           return info.param.name;
                         });

}  // namespace
}  // namespace dispmvs
