#pragma once
// The fixed validation set of a run (generated scenes at full difficulty,
// from TrainOptions::validation_seed_base on) and the network's numbers on
// it: the depth metrics per depth-range widening and the coarse matching
// accuracy. Apart from the loop (trainer.cc) because it has two callers: the
// validations inside a run and EvaluateWeights' table.
//
// Internal to train/: the public interface is trainer.h.

#include <cstdint>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "model/confidence_model.h"
#include "model/dispmvs_net.h"
#include "model/matching_loss.h"
#include "synth/generator.h"
#include "train/trainer.h"

namespace dispmvs::train::internal {

// A CPU generator seeded with `seed`: the network's random initialisation in a forward pass.
torch::Generator CpuGenerator(uint64_t seed);

// Throws std::invalid_argument ("weights of config 'NAME' need a depth-range
// hint: " + `consequence`) when `widening` is 0 (no hint) and the weights
// need one.
void CheckHintAvailable(model::DispMvsNet& net, double widening, const std::string& consequence);

// Adds `result`'s counts (pairs, top-1 and peak hits; not the loss) to `sums`:
// the coarse matching accuracy over several scenes or bands.
void AddMatchCounts(const model::MatchingLossResult& result, model::MatchingLossResult* sums);

// The validation scenes of `options` (its size, view count, scene count and seed base).
std::vector<synth::SynthSample> ValidationScenes(const TrainOptions& options, torch::Device device);

// One table row per widening; the coarse accuracy measured once for all.
// With `fill_model` (and eval_refinement ncc): the refined depth filled from
// confident planes by options.eval_fill_options, the confidence by that
// model (model/confident_plane_fill.h).
std::vector<WideningResult> Validate(model::DispMvsNet& net, const std::vector<synth::SynthSample>& scenes,
                                     const TrainOptions& options, const std::vector<double>& widenings,
                                     bool look_from_sources, const model::ConfidenceModel* fill_model = nullptr);

}  // namespace dispmvs::train::internal
