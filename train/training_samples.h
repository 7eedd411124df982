#pragma once
// What a training step trains on: generated scenes (synth/), with photo
// textures when the run has a photo folder, and samples of an MVSNet-format
// data set (mvsnet_dataset.h), each following from the run's seed, the step
// and the sample's index alone. Apart from the loop (trainer.cc) because it
// is where a run's data comes from, not how a step learns from it; the
// validation scenes (validation.h) are drawn by the same generator.
//
// Internal to train/: the public interface is trainer.h.

#include <cstdint>
#include <optional>
#include <vector>

#include <torch/torch.h>

#include "synth/generator.h"
#include "train/mvsnet_dataset.h"
#include "train/train_log.h"
#include "train/trainer.h"

namespace dispmvs::train::internal {

// The bit that every training seed has and no validation seed (TrainingSampleSeed).
inline constexpr uint64_t kTopBit = uint64_t{1} << 63;

// Two seeds into one (SplitMix64: the same on every platform).
uint64_t Mix(uint64_t a, uint64_t b);

// The sample with `count` of its sources (all when count >= their number),
// drawn without replacement by `seed` and kept in their order; the
// reference, and so its depth range, stays.
synth::SynthSample WithSourceCount(const synth::SynthSample& sample, int64_t count, uint64_t seed);

// The generator's configuration for the size and view count of `options` (checked).
synth::SynthConfig SynthConfigFor(const TrainOptions& options);

// The sample for `seed`, or for the first usable seed after it in the
// sequence seed, Mix(seed, 1), Mix(seed, 2), ..., each with the top bit of
// `seed` kept, so that training and validation seeds stay disjoint.
synth::SynthSample GenerateUsableSample(const synth::SynthConfig& config, uint64_t seed,
                                        torch::Device device);

// The MVSNet data set of a run (TrainOptions::mvsnet_root) and the reference
// views that samples are drawn from.
struct MvsnetSource {
  MvsnetDataset dataset;
  std::vector<MvsnetViewRef> views;
  MvsnetSampleOptions sample_options;
};

// Where the training samples come from: generated scenes (with photo
// textures when the run has a photo folder) and the MVSNet data set, if any.
// Each generated scene serves options.scene_reuse consecutive steps.
class TrainingSamples {
 public:
  // Loads the run's photos, opens its data set and logs what they hold.
  TrainingSamples(const TrainOptions& options, torch::Device device, Logger& log);

  // The batch's samples of training step `step`: the scenes of its group,
  // each with the step's view as the reference.
  std::vector<synth::SynthSample> ForStep(int64_t step);

 private:
  const TrainOptions& options_;
  torch::Device device_;
  synth::SynthConfig synth_config_;
  std::optional<MvsnetSource> mvsnet_;
  int64_t cached_group_ = -1;
  std::vector<synth::SynthSample> cached_scenes_;
};

}  // namespace dispmvs::train::internal
