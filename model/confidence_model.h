#pragma once
// A confidence that means something: the probability that a pixel's depth
// is within 2 % of the truth, predicted from what the network and the
// photometric refinement saw there.
//
// Why: the network's own confidence (the softmax mass of its last match
// around the peak) stays high where matching is ambiguous or impossible:
// all-black views got confident, consistent depth, so neither the geometric
// filter's --min_confidence nor a user could drop such pixels. The
// refinement measures what the images say at the chosen depth: how well the
// windows correlate there (NCC, invariant to gain and offset), whether a
// depth nearby correlates better (ambiguity), and whether the reference
// window has texture at all. A logistic model over these features, fitted on
// generated scenes against whether the depth is within 2 % (the metric the
// project reports), turns them into one calibrated number in [0, 1].
//
// The model's coefficients live in the weights file's metadata (key
// "confidence_model"), beside the network they were fitted for:
// `dispmvs_train --fit_confidence WEIGHTS --output OUT` writes them. Weights
// without them give the network's confidence, as before.

#include <string>
#include <vector>

#include <torch/torch.h>

#include "model/photometric_refinement.h"

namespace dispmvs::model {

// The features of every pixel, [B,kConfidenceFeatures,H,W] float:
//   0  1 (the intercept)
//   1  the network's confidence
//   2  the NCC at the output depth (PhotometricRefinement::output_score), 0 where none
//   3  1 where that NCC was computed, else 0
//   4  how much better the best NCC of the search was than that (>= 0; a
//      depth nearby that correlates better: ambiguity), 0 where none
//   5  1 where the refinement replaced the network's depth
//   6  log of the reference window's grey standard deviation (floored at 1e-3)
//   7  the output NCC squared (the step from "uncertain" to "sure" is not linear)
inline constexpr int64_t kConfidenceFeatures = 8;
torch::Tensor ConfidenceFeatures(const torch::Tensor& network_confidence, const PhotometricRefinement& refinement);

// The logistic model's coefficients, one per feature; empty = no model.
struct ConfidenceModel {
  std::vector<double> coefficients;

  bool empty() const { return coefficients.empty(); }
  // "c0 c1 ... c7" with 17 significant digits; FromText throws
  // std::invalid_argument on anything but kConfidenceFeatures finite numbers.
  std::string ToText() const;
  static ConfidenceModel FromText(const std::string& text);
};

// The weights file's metadata key of the coefficients.
inline constexpr char kConfidenceModelKey[] = "confidence_model";

// sigmoid(features . coefficients): [B,1,H,W] in (0, 1). Throws
// std::invalid_argument for an empty model or features of another width.
torch::Tensor PredictConfidence(const ConfidenceModel& model, const torch::Tensor& features);

// The confidence map of a refined depth map: PredictConfidence, and 0 where
// no window within kSignalRadius pixels has any image signal
// (PhotometricRefinement::signal_support is 0). There the depth comes from
// nothing the images show: an all-black or all-white view, a clipped sky. A
// fitted model cannot learn that from generated scenes, whose sensor noise
// gives every window some signal (their flat textures are still matched
// through their edges and shading: about half of the pixels more than 32
// pixels from any texture are within 2 % there).
torch::Tensor ConfidenceMap(const ConfidenceModel& model, const torch::Tensor& network_confidence,
                            const PhotometricRefinement& refinement);

// The same from features already computed (ConfidenceFeatures) and the
// refinement's signal_support, [B,1,H,W]: what the fit's curves rank.
torch::Tensor ConfidenceFromFeatures(const ConfidenceModel& model, const torch::Tensor& features,
                                     const torch::Tensor& signal_support);

// Maximum-likelihood logistic regression (Newton's method, a small ridge on
// every coefficient but the intercept so that a feature constant in the data
// stays bounded). features [M,kConfidenceFeatures], labels [M] in {0, 1}.
// Throws std::invalid_argument on mismatched shapes or labels of one class.
ConfidenceModel FitConfidenceModel(const torch::Tensor& features, const torch::Tensor& labels,
                                   double ridge = 1e-3, int max_iterations = 50);

// The model stored in a weights file (empty when it has none); throws
// std::runtime_error naming the file when the stored text is malformed.
ConfidenceModel ReadConfidenceModel(const std::string& weights_path);

// Copies the weights file `input` to `output` with `model` in its metadata
// (replacing any model there); the tensors and other metadata unchanged.
void WriteConfidenceModel(const std::string& input, const std::string& output, const ConfidenceModel& model);

}  // namespace dispmvs::model
