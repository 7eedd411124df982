#include "train/confidence_fit.h"

#include <chrono>
#include <cstdio>
#include <stdexcept>

#include "model/photometric_refinement.h"
#include "train/batch.h"
#include "train/training_samples.h"
#include "train/validation.h"

namespace dispmvs::train {
namespace {

// The tolerance the confidence predicts: the < 2 % the project reports.
constexpr double kTolerance = 0.02;

// A fit scene's own seed for the network's initialisation and source subset,
// apart from any training run's.
constexpr uint64_t kFitSalt = 0xC0F1D5u;

// One scene's pixels: features [M,F] (the network's confidence is feature
// 1), whether each is within the tolerance, and the refinement's signal
// support, over the predicted pixels with ground truth.
struct ScenePixels {
  torch::Tensor features, correct, signal_support;
};

ScenePixels RunScene(model::DispMvsNet& net, const synth::SynthSample& scene, uint64_t seed,
                     const TrainOptions& options, int64_t stride) {
  const TrainingBatch batch = MakeBatch({scene}, 1.0);
  const auto output = net->forward(batch.input, internal::CpuGenerator(seed));
  const model::PhotometricRefinement refinement =
      model::RefineDepthPhotometrically(batch.input, output, options.eval_refinement_options);
  const auto every = [&](const torch::Tensor& t) {  // [1,C,H,W] -> every stride-th pixel
    using torch::indexing::Slice;
    return t.index({Slice(), Slice(), Slice(0, torch::indexing::None, stride), Slice(0, torch::indexing::None, stride)});
  };
  const torch::Tensor features = every(model::ConfidenceFeatures(output.confidence, refinement)).cpu();
  const torch::Tensor depth = every(refinement.depth).cpu().to(torch::kFloat64);
  const torch::Tensor truth = every(batch.gt_depth).cpu().to(torch::kFloat64);
  const torch::Tensor used = (every(refinement.valid).cpu() & every(batch.gt_valid).cpu()).flatten();
  const torch::Tensor within = ((depth - truth).abs() < kTolerance * truth).flatten();
  ScenePixels pixels;
  pixels.features = features.permute({0, 2, 3, 1}).reshape({-1, model::kConfidenceFeatures}).index({used});
  pixels.correct = within.index({used});
  pixels.signal_support = every(refinement.signal_support).cpu().flatten().index({used});
  return pixels;
}

ScenePixels RunScenes(model::DispMvsNet& net, const std::vector<synth::SynthSample>& scenes, uint64_t seed_base,
                      const TrainOptions& options, int64_t stride, const std::string& what, std::ostream& log) {
  std::vector<torch::Tensor> features, correct, support;
  for (size_t i = 0; i < scenes.size(); ++i) {
    const auto start = std::chrono::steady_clock::now();
    const ScenePixels p = RunScene(net, scenes[i], seed_base + i, options, stride);
    features.push_back(p.features);
    correct.push_back(p.correct);
    support.push_back(p.signal_support);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    char line[160];
    std::snprintf(line, sizeof line, "%s scene %zu/%zu: %lld pixels, %lld within 2 %% (%.1f s)", what.c_str(), i + 1,
                  scenes.size(), static_cast<long long>(p.correct.size(0)),
                  static_cast<long long>(p.correct.sum().item<int64_t>()), seconds);
    log << line << std::endl;
  }
  if (features.empty()) throw std::invalid_argument("confidence fit: no " + what + " scenes");
  return {torch::cat(features), torch::cat(correct), torch::cat(support)};
}

ConfidenceCurves Curves(const ScenePixels& pixels, const model::ConfidenceModel& model) {
  ConfidenceCurves curves;
  curves.pixels = pixels.correct.size(0);
  curves.network = ShareCorrectAtCoverage(pixels.features.select(1, 1), pixels.correct, kConfidenceCoverages);
  // The pixels as one [1,F,M,1] map, ranked as dispmvs_colmap writes them.
  const torch::Tensor predicted =
      model::ConfidenceFromFeatures(model, pixels.features.t().reshape({1, model::kConfidenceFeatures, -1, 1}),
                                    pixels.signal_support.view({1, 1, -1, 1}))
          .flatten();
  curves.model = ShareCorrectAtCoverage(predicted, pixels.correct, kConfidenceCoverages);
  return curves;
}

}  // namespace

std::vector<double> ShareCorrectAtCoverage(const torch::Tensor& confidence, const torch::Tensor& correct,
                                           const std::vector<double>& coverages) {
  if (confidence.numel() != correct.numel()) {
    throw std::invalid_argument("ShareCorrectAtCoverage: confidence and correct differ in size");
  }
  std::vector<double> shares;
  const int64_t m = confidence.numel();
  if (m == 0) return std::vector<double>(coverages.size(), 0.0);
  // Stable: equal confidences keep their order, so a constant confidence
  // ranks pixels as they come.
  const torch::Tensor order =
      std::get<1>(confidence.flatten().to(torch::kFloat64).sort(/*stable=*/true, /*dim=*/0, /*descending=*/true));
  const torch::Tensor hits = correct.flatten().to(torch::kFloat64).index_select(0, order).cumsum(0);
  for (const double coverage : coverages) {
    if (!(coverage > 0 && coverage <= 1)) {
      throw std::invalid_argument("ShareCorrectAtCoverage: coverages must be in (0, 1]");
    }
    const int64_t kept = std::max<int64_t>(1, static_cast<int64_t>(std::llround(coverage * static_cast<double>(m))));
    shares.push_back(hits[kept - 1].item<double>() / static_cast<double>(kept));
  }
  return shares;
}

std::vector<synth::SynthSample> ConfidenceFitScenes(const TrainOptions& options, int64_t count,
                                                    torch::Device device) {
  const synth::SynthConfig config = internal::SynthConfigFor(options);
  std::vector<synth::SynthSample> scenes;
  for (int64_t i = 0; i < count; ++i) {
    const uint64_t seed = TrainingSampleSeed(options.seed ^ kFitSalt, i, 0);
    scenes.push_back(internal::WithSourceCount(internal::GenerateUsableSample(config, seed, device),
                                               TrainingSourceCountAt(options, i), internal::Mix(seed, kFitSalt)));
  }
  return scenes;
}

ConfidenceFit FitConfidenceOnScenes(model::DispMvsNet& net, const std::vector<synth::SynthSample>& fit_scenes,
                                    const std::vector<synth::SynthSample>& validation_scenes,
                                    const TrainOptions& options, std::ostream& log) {
  if (options.eval_refinement != "ncc") {
    throw std::invalid_argument("the confidence model reads the photometric refinement: use --eval_refinement ncc");
  }
  const bool was_training = net->is_training();
  net->eval();
  torch::NoGradGuard no_grad;
  // Every second pixel of every second row: neighbours are nearly the same
  // sample, and a quarter keeps the fit's memory small.
  const ScenePixels fit = RunScenes(net, fit_scenes, options.seed ^ kFitSalt, options, 2, "fit", log);
  ConfidenceFit result;
  result.fit_scenes = static_cast<int64_t>(fit_scenes.size());
  result.fit_pixels = fit.correct.size(0);
  result.fit_share_correct = fit.correct.to(torch::kFloat64).mean().item<double>();
  result.model = model::FitConfidenceModel(fit.features, fit.correct);
  result.fit = Curves(fit, result.model);
  // The validation table's seeds, so the curves are of the table's maps.
  const ScenePixels validation =
      RunScenes(net, validation_scenes, options.validation_seed_base, options, 1, "validation", log);
  result.validation = Curves(validation, result.model);
  net->train(was_training);
  return result;
}

std::string FormatConfidenceCurves(const std::string& label, const ConfidenceCurves& curves) {
  std::string text = label + ": share within 2 % at coverage 50 / 75 / 90 / 100 %:";
  char number[32];
  for (const auto* row : {&curves.network, &curves.model}) {
    text += row == &curves.network ? " network" : ", model";
    for (const double share : *row) {
      std::snprintf(number, sizeof number, " %.4f", share);
      text += number;
    }
  }
  return text + " (" + std::to_string(curves.pixels) + " pixels)";
}

}  // namespace dispmvs::train
