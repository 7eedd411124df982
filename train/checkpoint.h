#pragma once
// A run's checkpoints (the directory layout is in trainer.h): their paths,
// the run settings that a checkpoint records and a resumed run must match,
// and saving, loading and restoring them. Apart from the loop (trainer.cc)
// because what makes two runs the same run is a question of its own, whose
// answer (SettingBeforeItExisted) grows with every new setting.
//
// Internal to train/: the public interface is trainer.h.

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

#include <torch/torch.h>

#include "model/config.h"
#include "model/dispmvs_net.h"
#include "train/train_log.h"
#include "train/trainer.h"

namespace dispmvs::train::internal {

// The settings that change what a step computes: a checkpoint can only be
// resumed by a run with the same ones (the total step count may differ).
// Computed once per run (they read the init weights and list the photo
// folder), then passed to every checkpoint.
using Settings = std::map<std::string, std::string>;
Settings RunSettings(const TrainOptions& o);

// Writes checkpoint `step` and then retires the older ones: their weights
// are kept under KeptWeightsPath when their step is a multiple of
// keep_weights_every (> 0), removed otherwise; their optimiser state goes.
void SaveCheckpoint(const std::filesystem::path& dir, int64_t step, model::DispMvsNet& net,
                    const model::ModelConfig& config, torch::optim::Adam& optimizer, const Settings& settings,
                    int64_t keep_weights_every);

// The weights and Adam moments a run starts from: its last complete
// checkpoint, else --init_weights, else the seeded random ones already in
// `net`. Returns the first step to run.
int64_t RestoreRun(const TrainOptions& options, const std::filesystem::path& dir, const Settings& settings,
                   model::DispMvsNet& net, torch::optim::Adam& optimizer, torch::Device device, Logger& log);

}  // namespace dispmvs::train::internal
