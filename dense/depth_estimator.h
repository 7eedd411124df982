#pragma once
// The DispMVS network as a depth-map estimator for one stereo problem of a
// COLMAP workspace: loads the weights once, then per problem turns the
// workspace's images and cameras into the network's input and its output
// into COLMAP dense arrays. LibTorch stays behind this interface.

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/depth_range.h"
#include "model/fine_stage_bands.h"
#include "model/large_block_cache.h"
#include "model/photometric_refinement_options.h"

namespace dispmvs::dense {

struct EstimatorOptions {
  // Weights (safetensors with the model configuration in its metadata).
  std::string model_path;
  std::string device = "cpu";  // cpu, cuda or cuda:<index>
  int threads = 0;             // intra-op threads on the CPU; 0 = one per core
  // GRU iterations per stage; 0 = those the weights were trained with.
  int coarse_iterations = 0;
  int fine_iterations = 0;
  // Arithmetic of the GRU update's convolutions: "auto" (bf16 on a CPU with
  // native bf16 instructions, fp32 elsewhere), "fp32" or "bf16"
  // (model/precision.h; the 20-scene table is the same in both,
  // docs/benchmarks.md).
  std::string precision = "auto";
  // Budget for the matching encoder's features kept across problems (an
  // image that is the source of several references is encoded once), MiB;
  // 0 = encode every view of every problem.
  int feature_cache_mb = 256;
  // On the CPU: budget of freed tensor blocks of 32 MiB and more kept for
  // reuse, MiB (model/large_block_cache.h); 0 = none kept, every such block
  // mapped afresh by the C library (several times slower above about 2
  // megapixels).
  int tensor_cache_mb = static_cast<int>(model::LargeBlockCacheOptions{}.max_cached_bytes >> 20);
  // The network's fine stage in bands of rows of about this many megapixels
  // each, halos included (DispMvsNet::set_fine_band_pixels): less memory at
  // large sizes for a little more time; an image smaller than one band runs
  // whole, as with 0 (never in bands).
  double band_megapixels = model::kDefaultBandMegapixels;
  // What follows the network: "ncc", a short search along the epipolar lines
  // around its depth scored by normalised cross-correlation of the images
  // (model/photometric_refinement.h), or "none", the network's depth as it is
  // (the paper's behaviour).
  std::string refinement = "ncc";
  model::PhotometricRefinementOptions refinement_options;
  // The confidence map: "model", the weights' confidence model
  // (model/confidence_model.h: the probability that the depth is within
  // 2 %, from the network's confidence and the refinement's correlation and
  // texture) where the weights carry one and the refinement runs, else the
  // network's; or "network", the network's own (the softmax mass of its last
  // match around the peak).
  std::string confidence = "model";
  // With the confidence model: pixels it gives little chance take the plane
  // of the nearest confident pixel (model/confident_plane_fill.h); the
  // confidence map keeps their low confidence. below = 0: off.
  model::ConfidentPlaneFillOptions fill_options;

  // Throws std::invalid_argument naming the command-line option at fault.
  void Check() const;
};

// One view of a problem, ready for the network: an RGB CV_32FC3 image in
// [0, 1] on COLMAP's dense index grid (colmap_io::ResampleToDenseIndexGrid),
// its COLMAP intrinsics at that size, and its world-to-camera pose.
struct ProblemView {
  // The workspace image it shows, so that its encoder features can be reused
  // by later problems at the same size; -1: not reused.
  int64_t image_id = -1;
  cv::Mat image;
  Eigen::Matrix3d K;
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
};

struct DepthEstimate {
  colmap_io::DenseArray depth;       // 0 where the network has no valid depth
  colmap_io::DenseArray confidence;  // in [0, 1], 0 where depth is 0
};

class DepthEstimator {
 public:
  // Loads the weights onto the device. Throws std::invalid_argument for bad
  // options or an unavailable device, std::runtime_error for weights that are
  // missing, malformed or do not match the network they describe.
  explicit DepthEstimator(const EstimatorOptions& options);
  // Whether the confidence maps come from the weights' confidence model
  // (EstimatorOptions::confidence), not the network's.
  bool UsesConfidenceModel() const;
  ~DepthEstimator();
  DepthEstimator(const DepthEstimator&) = delete;
  DepthEstimator& operator=(const DepthEstimator&) = delete;

  // views[0] is the reference, the others its sources (at least one); all
  // images have the reference's size. `seed` drives the random
  // initialisation, so a view's result does not depend on the order or the
  // machine the views are processed on. A given hint must be valid (0 <
  // d_min < d_max, finite); it is always passed to the network. Without one
  // the network gets no depth range, which model v2 weights (init = match)
  // accept; weights that need one (NeedsDepthRange()) throw
  // std::invalid_argument naming --depth_min. Non-finite network outputs
  // read as "no depth". `views` is taken by value and each image released
  // once copied into the network's input: a caller that moves its views in
  // does not hold a second copy of the pixels through the estimate (five
  // float images of 24 megapixels are 1.4 GB); one that copies them (cv::Mat
  // shares its pixels) keeps them.
  // `step`, if set, is called as each step begins ("encoders", "network",
  // "refinement"), so that a caller can say what a long view is doing.
  using StepCallback = std::function<void(const std::string& step)>;
  DepthEstimate Estimate(std::vector<ProblemView> views,
                         const std::optional<colmap_io::DepthRange>& hint, uint64_t seed,
                         const StepCallback& step = {});

  // Whether the loaded weights need a depth-range hint (the paper's random
  // initialisation) or not (model v2's initialisation from matches).
  bool NeedsDepthRange() const;

  struct WeightsInfo {
    std::string name;                // the configuration's name, e.g. "small"
    bool needs_depth_range = true;   // see NeedsDepthRange()
  };
  // Reads only the header of the weights file: throws std::runtime_error
  // ("cannot use the weights PATH: ...") when it is missing or malformed, so
  // a run can fail before it prints or writes anything.
  static WeightsInfo CheckWeightsFile(const std::string& model_path);

  // "small, 1675558 parameters, 8+2 iterations, cpu" for logs.
  std::string Describe() const;

  // How often the matching encoder ran, and how often its features were
  // reused from an earlier problem (EstimatorOptions::feature_cache_mb).
  struct EncoderUse {
    int64_t encoded = 0;
    int64_t reused = 0;
    double peak_cache_mb = 0;
  };
  EncoderUse encoder_use() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dispmvs::dense
