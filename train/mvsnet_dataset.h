#pragma once
// MVSNet-format data sets (the layout of the DTU and BlendedMVS releases
// prepared for MVSNet) as training samples, next to the generated scenes.
//
// A scan is a folder with
//   images/00000000.jpg|jpeg|png ...  (or blended_images/, BlendedMVS' name)
//   cams/00000000_cam.txt ...         one per view, see ParseMvsnetCamera
//   pair.txt                          (or cams/pair.txt, as in BlendedMVS)
//   depths/00000000.pfm ...           optional ground truth (or
//                                     rendered_depth_maps/, depth_gt/)
// and a data set root is either a scan itself or a folder of scans (its
// immediate sub-folders that are scans, in name order).
//
// Camera convention: MVSNet's intrinsics put the centre of pixel (row i,
// col j) at (x, y) = (j, i), like the network (model/geometry.h), so they
// are used as they are; the extrinsics map world to camera coordinates. A
// camera file describes the image stored next to it, at its stored size.
//
// Only image decoding needs more than LibTorch and the standard library: it
// uses OpenCV when the build found it (DISPMVS_HAVE_OPENCV). Without it,
// reading an image throws, and everything else (the parsers, the resizing)
// still works, so train/ keeps building on a machine with LibTorch alone.
//
// Errors: std::runtime_error naming the file (and the line, for the text
// formats) on a missing, truncated or malformed file; std::invalid_argument
// on bad arguments.

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "synth/generator.h"

namespace dispmvs::train {

// ---------------------------------------------------------------- cam.txt

// One cam.txt:
//   extrinsic
//   4 lines of the 4x4 world-to-camera matrix
//   intrinsic
//   3 lines of the 3x3 K
//   DEPTH_MIN DEPTH_INTERVAL [DEPTH_NUM [DEPTH_MAX]]
// Blank lines between the parts are optional. Every number must be finite;
// the last extrinsic row must be 0 0 0 1, its rotation orthonormal (to
// 1e-2: the files print a few digits), K upper triangular with fx, fy > 0
// and a last row 0 0 1, DEPTH_MIN > 0 and the range non-empty.
struct MvsnetCamera {
  std::array<double, 16> world_to_camera{};  // row-major 4x4
  std::array<double, 9> intrinsics{};        // row-major 3x3
  double depth_min = 0;
  double depth_interval = 0;
  int64_t depth_num = 192;  // when the file does not give it
  // DEPTH_MAX if given, else depth_min + depth_interval * (depth_num - 1).
  double depth_max = 0;
};

// `source` names the text in error messages (normally its path).
MvsnetCamera ParseMvsnetCamera(const std::string& text, const std::string& source);
MvsnetCamera ReadMvsnetCamera(const std::filesystem::path& path);

// ---------------------------------------------------------------- pair.txt

// One entry of pair.txt: a reference view and its source views, best first.
struct MvsnetViewPair {
  int64_t reference = 0;
  std::vector<int64_t> sources;
  std::vector<double> scores;  // one per source, as listed
};

// pair.txt: a line with the view count V, then per view a line with the
// reference index and a line "K src0 score0 src1 score1 ...". Every index
// must be in [0, V), each reference listed once, no source twice or equal to
// its reference, every score finite; nothing may follow the V entries.
std::vector<MvsnetViewPair> ParseMvsnetPairs(const std::string& text, const std::string& source);
std::vector<MvsnetViewPair> ReadMvsnetPairs(const std::filesystem::path& path);

// ---------------------------------------------------------------- PFM

// A PFM image in memory: rows top to bottom (the file stores them bottom to
// top), channels interleaved.
struct PfmImage {
  int64_t height = 0, width = 0, channels = 1;  // "Pf": 1 channel, "PF": 3
  std::vector<float> values;                    // height * width * channels
};

// Header "Pf" or "PF", "W H", scale (negative: little-endian data, positive:
// big-endian; its magnitude is not applied), one whitespace byte, then
// exactly W * H * channels 4-byte floats.
PfmImage ParsePfm(const std::string& bytes, const std::string& source);
PfmImage ReadPfm(const std::filesystem::path& path);

// A ground-truth depth map: a 1-channel PFM of finite values >= 0 (0: no
// ground truth) as a [1,H,W] float tensor.
torch::Tensor ReadMvsnetDepth(const std::filesystem::path& path);

// ---------------------------------------------------------------- images

// Whether this build can decode images (it found OpenCV).
bool MvsnetImageDecodingAvailable();
// Throws std::runtime_error("built without OpenCV: MVSNet datasets need
// image decoding") unless MvsnetImageDecodingAvailable().
void RequireMvsnetImageDecoding();
// An 8- or 16-bit grey, RGB or RGBA image as [3,H,W] float RGB in [0,1].
torch::Tensor ReadMvsnetImage(const std::filesystem::path& path);

// ------------------------------------------------- fitting to the input size

// How a stored view becomes a height x width network input: resized, keeping
// the aspect ratio as nearly as whole pixel counts allow, until it covers
// height x width, then cropped about the centre. The resize samples with
// pixel centres aligned (resized pixel i covers original [i, i + 1) / scale),
// so a point at original x is at (x + 0.5) * scale_x - 0.5 - crop_left.
struct ViewFit {
  int64_t resized_height = 0, resized_width = 0;  // before the crop
  int64_t crop_top = 0, crop_left = 0;
  int64_t height = 0, width = 0;   // after the crop
  double scale_y = 1, scale_x = 1;  // resized / stored, per axis (exact ratios)
};

ViewFit PlanViewFit(int64_t stored_height, int64_t stored_width, int64_t height, int64_t width);
// K of the fitted view, exact for the resize above:
//   K' = [[sx, 0, 0.5 sx - 0.5 - crop_left], [0, sy, 0.5 sy - 0.5 - crop_top], [0, 0, 1]] K.
std::array<double, 9> FitIntrinsics(const std::array<double, 9>& intrinsics, const ViewFit& fit);
// [C,h,w] float -> [C,height,width]: bilinear, antialiased when shrinking.
torch::Tensor FitImage(const torch::Tensor& image, const ViewFit& fit);
// [1,h,w] -> [1,height,width]: nearest pixel (depths are not blended across
// edges, and 0 stays "no ground truth").
torch::Tensor FitDepth(const torch::Tensor& depth, const ViewFit& fit);

// ---------------------------------------------------------------- data sets

struct MvsnetScan {
  std::filesystem::path dir;
  std::string name;  // dir's folder name
  std::vector<MvsnetViewPair> pairs;                // pair.txt's order
  std::vector<MvsnetCamera> cameras;                // by view index
  std::vector<std::filesystem::path> images;        // by view index
  std::vector<std::filesystem::path> depths;        // by view index; empty: no ground truth
};

struct MvsnetDataset {
  std::filesystem::path root;
  std::vector<MvsnetScan> scans;
};

// Reads every pair.txt and cam.txt and finds every view's image and depth
// map; throws if the root holds no scan, or a view of pair.txt has no camera
// file or image.
MvsnetDataset OpenMvsnetDataset(const std::filesystem::path& root);

// A reference view: scans[scan].pairs[pair].
struct MvsnetViewRef {
  size_t scan = 0;
  size_t pair = 0;
};

// The reference views usable for training with `num_sources` sources: with
// a ground-truth depth map and at least that many sources. Scan order, then
// pair.txt order.
std::vector<MvsnetViewRef> MvsnetTrainingViews(const MvsnetDataset& dataset, int64_t num_sources);

struct MvsnetSampleOptions {
  int64_t height = 128, width = 160;
  int64_t num_sources = 4;     // the first N sources of pair.txt
  bool source_depths = false;  // also read the sources' depth maps (else 0)
  torch::ScalarType dtype = torch::kFloat;

  // Throws std::invalid_argument on sizes or counts out of range.
  void Check() const;
};

// The sample of one reference view, laid out like a generated one
// (synth::SynthSample): view 0 the reference, then its first N sources; every
// view fitted to height x width (PlanViewFit); depth range from the
// reference's cam.txt; depths 0 where there is no ground truth; scale 1 and
// rig "mvsnet".
synth::SynthSample LoadMvsnetSample(const MvsnetDataset& dataset, const MvsnetViewRef& view,
                                    const MvsnetSampleOptions& options, torch::Device device);

// Which training sample a sample seed stands for: with probability
// `fraction` an index into `num_views` training views, else nullopt (a
// generated scene). A function of its arguments alone.
std::optional<size_t> ChooseMvsnetView(uint64_t sample_seed, double fraction, size_t num_views);

}  // namespace dispmvs::train
