#pragma once
// Fitting the confidence model (model/confidence_model.h) to a network:
// `dispmvs_train --fit_confidence WEIGHTS --output OUT`. The network and the
// photometric refinement run on generated scenes drawn with training seeds
// (never the validation scenes), with the run's --source_counts mix, and the
// logistic model learns from every second pixel of every second row which of
// them have their depth within 2 % of the truth. Then both confidences, the
// network's and the model's, are ranked on the validation scenes: the share
// of pixels within 2 % among the most confident 50 / 75 / 90 / 100 % (the
// precision/coverage curve; a confidence that means something keeps the
// right pixels first).

#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "model/confidence_model.h"
#include "model/dispmvs_net.h"
#include "synth/generator.h"
#include "train/trainer.h"

namespace dispmvs::train {

// The coverages of every curve.
inline const std::vector<double> kConfidenceCoverages{0.5, 0.75, 0.9, 1.0};

// Share of `correct` pixels among the `coverage` fraction of pixels with the
// highest `confidence` (ties broken by position), for each coverage in
// (0, 1]. confidence, correct: [M] (correct bool or 0/1). Empty input gives
// zeros.
std::vector<double> ShareCorrectAtCoverage(const torch::Tensor& confidence, const torch::Tensor& correct,
                                           const std::vector<double>& coverages);

struct ConfidenceCurves {
  int64_t pixels = 0;                  // predicted pixels with ground truth
  std::vector<double> network, model;  // ShareCorrectAtCoverage at kConfidenceCoverages
};

struct ConfidenceFit {
  model::ConfidenceModel model;
  int64_t fit_scenes = 0, fit_pixels = 0;
  double fit_share_correct = 0;  // of the fit pixels, within 2 %
  ConfidenceCurves fit, validation;
};

// Runs `net` with the refinement of options.eval_refinement_options (which
// must be "ncc": the model reads the refinement) on `fit_scenes`, fits the
// model, and ranks both confidences on the fit and the validation scenes.
// Progress goes to `log`, a line per scene.
ConfidenceFit FitConfidenceOnScenes(model::DispMvsNet& net, const std::vector<synth::SynthSample>& fit_scenes,
                                    const std::vector<synth::SynthSample>& validation_scenes,
                                    const TrainOptions& options, std::ostream& log);

// `count` generated scenes for the fit: training seeds from `options.seed`
// (disjoint from the validation seeds), each with its
// TrainingSourceCountAt(options, i) sources.
std::vector<synth::SynthSample> ConfidenceFitScenes(const TrainOptions& options, int64_t count,
                                                    torch::Device device);

// Loads the weights as EvaluateWeights does, fits on `fit_scene_count`
// scenes and checks on the validation scenes of `options`.
ConfidenceFit FitConfidence(const std::string& weights_path, const TrainOptions& options,
                            int64_t fit_scene_count, std::ostream& log);

// "share within 2 % at coverage 50 / 75 / 90 / 100 %: network a b c d, model e f g h (M pixels)".
std::string FormatConfidenceCurves(const std::string& label, const ConfidenceCurves& curves);

}  // namespace dispmvs::train
