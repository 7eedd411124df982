#pragma once
// The DispMVS network: encoders, then a coarse (1/16) and a fine (1/4) stage
// of iterative E-flow updates with multi-view triangulation and fusion, then
// convex upsampling to full resolution (paper Sec. "DispMVS", Fig. 2).
//
// One iteration of a stage, for every source view i (batched):
//   eflow_i  = E-flow of the current fused inverse depth w (project w into
//              source i; base point and epipolar direction fixed per stage)
//   cost_i   = EpipolarCorrelation_i.Lookup(ref features, base, dir, eflow_i)
//   GRU      -> delta E-flow_i, weight logit_i
//   w_i      = TriangulateInverseDepth(source pixel of eflow_i + delta_i)
//   w        = FuseInverseDepths(w_i, logits)   (softmax over valid sources)
// w is detached before the next iteration (as the release and RAFT do); the
// GRU hidden state is not.
//
// How the coarse stage starts depends on ModelConfig::init. kRandom (the
// paper): a random inverse depth inside the depth-range hint, and the coarse
// correlation sampled in 2-D around the current match every iteration.
// kMatch (model v2): the coarse correlation is a 1-D volume along each
// source's whole epipolar segment (segment_correlation.h), computed once; the
// start is every source's best match along it, triangulated and fused with
// the matches' confidences as weights; no depth range is used at all. Model
// v2 also samples its feature maps where the encoder really puts its cells
// (StridedIntrinsics). Nothing is ever clipped to the hint. Pixels are invalid where no source gives a valid
// triangulation (w <= 0, non-finite, degenerate geometry); they carry their
// previous inverse depth into the next iteration and read 0 in the outputs.

#include <vector>

#include <torch/torch.h>

#include "model/config.h"
#include "model/encoder.h"
#include "model/fine_stage_bands.h"
#include "model/matching_loss.h"
#include "model/precision.h"
#include "model/stage_timer.h"
#include "model/update_block.h"

namespace dispmvs::model {

struct DispMvsInput {
  // [B,V,3,H,W], values in [0,1]; view 0 is the reference, views 1..V-1
  // (V >= 2) the sources. Any H, W >= 1: the network pads to multiples of 16
  // (replicating the border) and crops its outputs back.
  torch::Tensor images;
  // [B,V,3,3] intrinsics at full resolution in the pixel-index convention
  // (the centre of pixel (row i, col j) is (x, y) = (j, i)).
  torch::Tensor intrinsics;
  // [B,V,4,4] world-to-camera matrices [R T; 0 0 0 1]: X_cam = R X_world + T
  // (COLMAP's convention). Only the top 3x4 block is read.
  torch::Tensor extrinsics;
  // [B] positive depth range hint, depth_min < depth_max: used for the random
  // initialisation only (and by the loss for normalisation). May be left
  // undefined when the configuration does not need it
  // (!ModelConfig::NeedsDepthRange()).
  torch::Tensor depth_min;
  torch::Tensor depth_max;
  // Optional: the matching encoder's features of every view, coarse
  // [B*V, C, H'/16, W'/16] and fine [B*V, C', H'/4, W'/4] (H', W': the size
  // padded to multiples of 16), index b*V + view, as EncodeMatching() gives
  // them for each view. When set, forward() does not run the matching
  // encoder, so a caller that meets the same image in many problems (a
  // source of several references) encodes it once. Inference only: the
  // features carry no gradient to the encoder.
  FeaturePyramid matching_features;
};

struct DispMvsOutput {
  // Fused inverse depth after each iteration, upsampled to [B,1,H,W]: t_c
  // coarse entries then t_f fine ones, 0 where invalid. In training mode
  // (is_training()) every iteration is returned, for SequenceLoss; in eval
  // mode only the final one (saving the per-iteration upsampling).
  std::vector<torch::Tensor> inv_depths;
  torch::Tensor depth;  // [B,1,H,W] final depth, 0 where invalid
  torch::Tensor valid;  // [B,1,H,W] bool
  // [B,1,H,W] in [0,1], 0 where invalid: the fusion weight mass (softmax over
  // sources, at the last fine iteration) of the sources whose own triangulated
  // inverse depth agrees with the fused one within kAgreementTolerance
  // (relative), convex-upsampled like the depth. 1 = every source that the
  // network trusts agrees; with a single source it only says whether that
  // source triangulated validly.
  torch::Tensor confidence;
  // Model v2 in training mode: what the coarse stage (the segment volume)
  // and the fine stage (its first lookup window, level 0) matched, for the
  // matching loss (matching_loss.h). Empty otherwise.
  std::vector<StageMatching> matching;
  // Model v2 in training mode: the source pixel every fine iteration matched
  // in every source, [B*N,2,h,w] in fine-stage pixels (index b*N + i), for
  // the flow loss (matching_loss.h, SourceFlowLoss). Empty otherwise.
  std::vector<torch::Tensor> fine_source_xy;
};

// Motion from the reference (view 0) to every source view, from world-to-camera
// extrinsics [B,V,4,4]: X_s = R X_r + T with R = R_s R_r^T, T = T_s - R T_r.
// Returns R [B,V-1,3,3] and T [B,V-1,3] (geometry.h's pair convention).
struct RelativePoses {
  torch::Tensor R;
  torch::Tensor T;
};
RelativePoses ReferenceToSourcePoses(const torch::Tensor& extrinsics);

class DispMvsNetImpl : public torch::nn::Module {
 public:
  // Relative inverse-depth difference under which a source "agrees" with the
  // fused result, for the confidence.
  static constexpr double kAgreementTolerance = 0.02;
  // Both stages upsample by 4: 1/16 -> 1/4 and 1/4 -> 1.
  static constexpr int64_t kUpsampleFactor = 4;
  static constexpr int64_t kCoarseStride = 16;
  static constexpr int64_t kFineStride = 4;

  // Throws std::invalid_argument if config.Check() fails.
  explicit DispMvsNetImpl(const ModelConfig& config);

  // Throws std::invalid_argument on malformed input (shapes, V < 2, a depth
  // range that is not 0 < depth_min < depth_max, non-finite values).
  // `gen` drives the random initialisation (default generator if undefined).
  DispMvsOutput forward(const DispMvsInput& input, torch::Generator gen = {});

  // The matching encoder's features of images [B,3,H,W] in [0,1], padded as
  // forward() pads them and encoded one image at a time, as forward() does
  // in inference (no autograd): so features computed here and passed in
  // DispMvsInput::matching_features give bit-identical results.
  FeaturePyramid EncodeMatching(const torch::Tensor& images);

  // The coarse segment volume alone (matching encoder, no GRU), with the
  // encoder's real cell positions whatever the configuration: how well the
  // features match, for any design (training diagnostics). Same input checks
  // as forward().
  StageMatching CoarseMatching(const DispMvsInput& input);

  const ModelConfig& config() const { return config_; }
  // Changes the GRU iterations per stage of later passes (no parameter
  // depends on them): e.g. fewer coarse iterations in training than in
  // inference. Throws std::invalid_argument unless both are >= 1.
  void set_iterations(int64_t coarse, int64_t fine);

  // Inference (eval mode, no autograd): the fine stage and the final
  // upsampling run in bands of rows, each about `pixels` full-resolution
  // pixels with the rows its own ones depend on (FineBandHalo: 27 fine rows,
  // 108 pixels, on either side for 2 fine iterations), whenever the image
  // has more rows than one band. The fine stage's maps (hidden states,
  // correlation, the GRU's: 330 bytes per image pixel with four sources,
  // measured at 4000x3000) then never exist for the whole image; the cost is
  // the halos' share of the fine stage's time. The outputs agree with a
  // whole-image pass to float rounding. 0 (the default): the whole image at
  // once. Throws std::invalid_argument if pixels < 0.
  void set_fine_band_pixels(int64_t pixels);
  int64_t fine_band_pixels() const { return fine_band_pixels_; }

  // The arithmetic of the GRU update blocks' convolutions in later passes
  // (precision.h; fp32 by default): in bf16 a pass is about a sixth faster
  // on a CPU with native bf16 (docs/benchmarks.md). The encoders, the correlation and the
  // geometry stay fp32. Training may use it too (dispmvs_train --precision):
  // autograd runs through the rounded convolutions into the fp32 weights.
  void set_precision(Precision precision);
  Precision precision() const { return coarse_block_->precision(); }

  // Times the stages of every later forward pass into `timer` (not owned;
  // null detaches). For benchmarks: see stage_timer.h.
  void set_stage_timer(StageTimer* timer) { stage_timer_ = timer; }

 private:
  ModelConfig config_;
  MatchingEncoder matching_encoder_{nullptr};
  ContextEncoder context_encoder_{nullptr};
  UpdateBlock coarse_block_{nullptr};
  UpdateBlock fine_block_{nullptr};
  StageTimer* stage_timer_ = nullptr;
  int64_t fine_band_pixels_ = 0;
};
TORCH_MODULE(DispMvsNet);

}  // namespace dispmvs::model
