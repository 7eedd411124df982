#include "train/validation.h"

#include <ATen/CPUGeneratorImpl.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "model/confidence_model.h"
#include "model/confident_plane_fill.h"
#include "model/matching_loss.h"
#include "model/photometric_refinement.h"
#include "train/batch.h"
#include "train/source_pixel_metrics.h"
#include "train/training_samples.h"
#include "train/validation_metrics.h"

namespace dispmvs::train::internal {
namespace {

using model::DispMvsNet;

// Coarse matching accuracy on the validation scenes: the sums of
// model::MatchingLossResult over them. It does not depend on the
// depth-range hint, so it is measured once per validation, not once per
// widening.
model::MatchingLossResult CoarseMatchingAccuracy(DispMvsNet& net, const std::vector<synth::SynthSample>& scenes) {
  const bool was_training = net->is_training();
  net->eval();
  torch::NoGradGuard no_grad;
  model::MatchingLossResult sums;
  for (const auto& scene : scenes) {
    const auto batch = MakeBatch({scene}, 1.0);
    const model::StageMatching matching = net->CoarseMatching(batch.input);
    const auto truth = model::ComputeGroundTruthMatches(
        batch.gt_depths, batch.input.intrinsics, batch.input.extrinsics, matching.stride,
        matching.logits.size(2), matching.logits.size(3));
    AddMatchCounts(model::MatchingLoss(matching, truth), &sums);
  }
  net->train(was_training);
  return sums;
}

// The depth metrics of a WideningResult on the validation scenes with the
// hint widened by `widening` (0: no hint), with the network's iterations as
// they are. With `look_from_sources` (the evaluation table; training's
// validations log only the first line) also `seen`, `seen_share` and
// `source_pixels` (source_pixel_metrics.h).
WideningResult ValidateDepth(DispMvsNet& net, const std::vector<synth::SynthSample>& scenes,
                             const TrainOptions& options, double widening, bool look_from_sources,
                             const model::ConfidenceModel* fill_model) {
  CheckHintAvailable(net, widening, "no 'none' row for them");
  const bool was_training = net->is_training();
  net->eval();
  torch::NoGradGuard no_grad;
  ValidationDepthSums sums, seen_sums;
  SourcePixelCounts source_sums;
  for (size_t i = 0; i < scenes.size(); ++i) {
    const auto batch = MakeBatch({scenes[i]}, widening);
    // Same initialisation for a scene at every evaluation: the numbers differ
    // between evaluations only because the weights do.
    auto output = net->forward(batch.input, CpuGenerator(options.validation_seed_base + i));
    if (options.eval_refinement == "ncc") {
      const model::PhotometricRefinement refined =
          model::RefineDepthPhotometrically(batch.input, output, options.eval_refinement_options);
      output.depth = refined.depth;
      if (fill_model != nullptr) {
        const torch::Tensor confidence = model::ConfidenceMap(*fill_model, output.confidence, refined);
        output.depth = model::FillFromConfidentPlanes(output.depth, confidence, options.eval_fill_options).depth;
      }
    }
    sums += SumValidationDepth(output.depth, output.valid, batch.gt_depth, batch.gt_valid);
    if (!look_from_sources) continue;
    torch::Tensor seen;
    source_sums += CountSourcePixels(batch.gt_depths, batch.input.intrinsics,
                                     batch.input.extrinsics, output.depth, output.valid, &seen);
    seen_sums += SumValidationDepth(output.depth, output.valid, batch.gt_depth, seen);
  }
  net->train(was_training);
  WideningResult result;
  result.widening = widening;
  result.metrics = FinalizeValidation(sums);
  result.seen = FinalizeValidation(seen_sums);
  result.seen_share =
      sums.gt_pixels > 0 ? static_cast<double>(seen_sums.gt_pixels) / sums.gt_pixels : 0.0;
  result.source_pixels = SharesOf(source_sums);
  return result;
}

}  // namespace

void AddMatchCounts(const model::MatchingLossResult& result, model::MatchingLossResult* sums) {
  sums->count += result.count;
  sums->top1 += result.top1;
  sums->top2_peaks += result.top2_peaks;
  sums->top4_peaks += result.top4_peaks;
}

torch::Generator CpuGenerator(uint64_t seed) {
  return at::make_generator<at::CPUGeneratorImpl>(seed);
}

void CheckHintAvailable(DispMvsNet& net, double widening, const std::string& consequence) {
  if (widening == 0 && net->config().NeedsDepthRange()) {
    throw std::invalid_argument("weights of config '" + net->config().name +
                                "' need a depth-range hint: " + consequence);
  }
}

std::vector<synth::SynthSample> ValidationScenes(const TrainOptions& options, torch::Device device) {
  auto config = SynthConfigFor(options);
  config.supersampling = static_cast<int>(options.val_supersampling);
  std::vector<synth::SynthSample> scenes;
  for (int64_t i = 0; i < options.num_validation_scenes; ++i) {
    scenes.push_back(GenerateUsableSample(config, options.validation_seed_base + i, device));
  }
  return scenes;
}

std::vector<WideningResult> Validate(DispMvsNet& net, const std::vector<synth::SynthSample>& scenes,
                                     const TrainOptions& options, const std::vector<double>& widenings,
                                     bool look_from_sources, const model::ConfidenceModel* fill_model) {
  std::vector<WideningResult> results;
  for (double x : widenings) {
    results.push_back(ValidateDepth(net, scenes, options, x, look_from_sources, fill_model));
  }
  const model::MatchingLossResult coarse = CoarseMatchingAccuracy(net, scenes);
  const double counted = std::max(coarse.count, 1.0);
  for (auto& row : results) {
    row.coarse_top1 = coarse.top1 / counted;
    row.coarse_top2_peaks = coarse.top2_peaks / counted;
    row.coarse_top4_peaks = coarse.top4_peaks / counted;
    row.matching_count = coarse.count;
  }
  return results;
}

}  // namespace dispmvs::train::internal
