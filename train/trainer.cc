#include "train/trainer.h"

#include <ATen/CPUGeneratorImpl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <type_traits>

#include "model/config.h"
#include "model/device.h"
#include "model/dispmvs_net.h"
#include "model/host_allocator.h"
#include "model/loss.h"
#include "model/matching_loss.h"
#include "model/safetensors.h"
#include "synth/generator.h"
#include "synth/photo_folder.h"
#include "synth/rng.h"
#include "train/batch.h"
#include "train/source_pixel_metrics.h"
#include "train/mvsnet_dataset.h"

namespace dispmvs::train {
namespace {

namespace fs = std::filesystem;
using model::DispMvsNet;
using model::ModelConfig;

constexpr uint64_t kTopBit = uint64_t{1} << 63;
// A generated scene can show no surface at all in the reference view (no
// usable depth range); such draws are replaced by the next seed in a fixed
// sequence, so the replacement is deterministic too.
constexpr int kMaxDrawAttempts = 16;

// Two seeds into one (SplitMix64: the same on every platform).
uint64_t Mix(uint64_t a, uint64_t b) { return synth::SplitMix64(a ^ synth::SplitMix64(b)); }

// Seed of the network's random initialisation at training step `step`.
uint64_t TrainingInitSeed(uint64_t seed, int64_t step) {
  return Mix(Mix(seed, 0xD15A11u), static_cast<uint64_t>(step));
}

torch::Generator CpuGenerator(uint64_t seed) {
  return at::make_generator<at::CPUGeneratorImpl>(seed);
}

// Process CPU time (all threads), seconds.
double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

// The sample with view `reference` as its reference and the other views, in
// their order, as sources; the depth-range hint recomputed for it. Returns
// the sample unchanged for reference 0, or when that view sees no surface.
synth::SynthSample WithReference(const synth::SynthSample& sample, int64_t reference) {
  const int64_t views = sample.images.size(0);
  if (reference % views == 0) return sample;
  std::vector<int64_t> order{reference % views};
  for (int64_t v = 0; v < views; ++v) {
    if (v != reference % views) order.push_back(v);
  }
  const torch::Tensor index = torch::tensor(order, torch::kLong).to(sample.images.device());
  synth::SynthSample out = sample;
  out.images = sample.images.index_select(0, index);
  out.intrinsics = sample.intrinsics.index_select(0, index);
  out.world_to_camera = sample.world_to_camera.index_select(0, index);
  out.depths = sample.depths.index_select(0, index);
  std::tie(out.depth_min, out.depth_max) = synth::RobustDepthRange(out.depths[0]);
  if (!(out.depth_min > 0 && out.depth_min < out.depth_max)) return sample;
  return out;
}

synth::SynthConfig SynthConfigFor(const TrainOptions& options) {
  synth::SynthConfig config;
  config.height = options.height;
  config.width = options.width;
  config.num_views = static_cast<int>(options.num_sources + 1);
  config.Check();
  return config;
}

// The sample for `seed`, or for the first usable seed after it in the
// sequence seed, Mix(seed, 1), Mix(seed, 2), ..., each with the top bit of
// `seed` kept, so that training and validation seeds stay disjoint.
synth::SynthSample GenerateUsableSample(const synth::SynthConfig& config, uint64_t seed,
                                        torch::Device device) {
  const uint64_t top = seed & kTopBit;
  uint64_t attempt_seed = seed;
  for (int attempt = 0; attempt < kMaxDrawAttempts; ++attempt) {
    auto sample = synth::GenerateSample(config, attempt_seed, device);
    if (sample.depth_min > 0 && sample.depth_min < sample.depth_max) return sample;
    attempt_seed = (Mix(seed, static_cast<uint64_t>(attempt + 1)) & ~kTopBit) | top;
  }
  throw std::runtime_error("no usable synthetic scene after " + std::to_string(kMaxDrawAttempts) +
                           " draws from seed " + std::to_string(seed));
}

// The MVSNet data set of a run (TrainOptions::mvsnet_root) and the reference
// views that samples are drawn from.
struct MvsnetSource {
  MvsnetDataset dataset;
  std::vector<MvsnetViewRef> views;
  MvsnetSampleOptions sample_options;
};

// Opened once, before the first step, so that a bad data set fails the run
// at once rather than at the first step that happens to draw from it.
std::optional<MvsnetSource> OpenMvsnetSource(const TrainOptions& options, const synth::SynthConfig& synth_config) {
  if (options.mvsnet_root.empty()) return std::nullopt;
  RequireMvsnetImageDecoding();
  MvsnetSource source;
  source.dataset = OpenMvsnetDataset(options.mvsnet_root);
  source.views = MvsnetTrainingViews(source.dataset, options.num_sources);
  if (source.views.empty()) {
    throw std::runtime_error(options.mvsnet_root + ": no reference view with a ground-truth depth map and at least " +
                             std::to_string(options.num_sources) + " source views");
  }
  source.sample_options.height = options.height;
  source.sample_options.width = options.width;
  source.sample_options.num_sources = options.num_sources;
  source.sample_options.dtype = synth_config.dtype;  // batches mix both kinds
  return source;
}

// Sample `index` of scene group `group` (= step / scene_reuse): from the data
// set with probability mvsnet_fraction, else a generated scene; both the
// choice and the reference view follow from TrainingSampleSeed alone, so runs
// stay reproducible.
synth::SynthSample TrainingSample(const TrainOptions& options, const synth::SynthConfig& synth_config,
                                  const std::optional<MvsnetSource>& mvsnet, int64_t group, int64_t index,
                                  torch::Device device) {
  const uint64_t seed = TrainingSampleSeed(options.seed, group, index);
  if (mvsnet) {
    if (const auto view = ChooseMvsnetView(seed, options.mvsnet_fraction, mvsnet->views.size())) {
      return LoadMvsnetSample(mvsnet->dataset, mvsnet->views[*view], mvsnet->sample_options, device);
    }
  }
  return GenerateUsableSample(synth_config, seed, device);
}

void SetThreads(int64_t threads) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  torch::set_num_threads(static_cast<int>(threads));
}

std::string FormatDuration(double seconds) {
  const auto total = static_cast<int64_t>(std::max(0.0, seconds) + 0.5);
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%lld:%02lld:%02lld", static_cast<long long>(total / 3600),
                static_cast<long long>(total / 60 % 60), static_cast<long long>(total % 60));
  return buffer;
}

// Writes every line to the console stream and the log file.
class Logger {
 public:
  Logger(std::ostream& console, const fs::path& file) : console_(console), file_(file, std::ios::app) {
    if (!file_) throw std::runtime_error("cannot open log file " + file.string());
  }
  void Line(const std::string& line) {
    console_ << line << std::endl;
    file_ << line << std::endl;
  }

 private:
  std::ostream& console_;
  std::ofstream file_;
};

// ---------------------------------------------------------------- checkpoints

// "<prefix>-<step in nine digits>": steps are capped at 999'999'999 by Check().
std::string StepName(const char* prefix, int64_t step) {
  char buffer[48];
  std::snprintf(buffer, sizeof buffer, "%s-%09lld", prefix, static_cast<long long>(step));
  return buffer;
}
fs::path WeightsPath(const fs::path& dir, int64_t step) {
  return dir / (StepName("checkpoint", step) + ".safetensors");
}
fs::path OptimPath(const fs::path& dir, int64_t step) {
  return dir / (StepName("checkpoint", step) + ".optim.safetensors");
}
fs::path KeptWeightsPath(const fs::path& dir, int64_t step) {
  return dir / (StepName("weights", step) + ".safetensors");
}

// Steps of the complete checkpoints in `dir` (both files present), ascending.
std::vector<int64_t> CompleteCheckpoints(const fs::path& dir) {
  std::vector<int64_t> steps;
  const std::string prefix = "checkpoint-", suffix = ".safetensors";
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.size() != prefix.size() + 9 + suffix.size() || name.rfind(prefix, 0) != 0 ||
        name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0) {
      continue;
    }
    const std::string digits = name.substr(prefix.size(), 9);
    if (!std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; })) continue;
    const int64_t step = std::stoll(digits);
    if (fs::exists(OptimPath(dir, step))) steps.push_back(step);
  }
  std::sort(steps.begin(), steps.end());
  return steps;
}

// A folder (data set, photos) as a setting: its absolute path, so that a
// resumed run may name it relative to another working directory.
std::string AbsolutePathSetting(const std::string& root) {
  if (root.empty()) return "";
  std::error_code error;
  const fs::path canonical = fs::weakly_canonical(fs::absolute(root), error);
  return (error ? fs::absolute(root).lexically_normal() : canonical).string();
}

// 64-bit FNV-1a: a stable fingerprint (not a security hash) of what a
// setting names.
struct Fnv1a64 {
  uint64_t value = 14695981039346656037ull;
  void Add(const char* data, size_t size) {
    for (size_t i = 0; i < size; ++i) value = (value ^ static_cast<unsigned char>(data[i])) * 1099511628211ull;
  }
  void Add(const std::string& text) { Add(text.data(), text.size()); }
};

// A weights file as a run setting: its size and a 64-bit FNV-1a hash of its
// bytes, so that the same weights under another path resume, and other
// weights under the same path do not.
std::string InitWeightsSetting(const std::string& path) {
  if (path.empty()) return "";
  std::ifstream file(path, std::ios::binary);
  if (!file) throw std::invalid_argument("init_weights: cannot read " + path);
  Fnv1a64 hash;
  uint64_t size = 0;
  char buffer[1 << 16];
  while (file.read(buffer, sizeof buffer) || file.gcount() > 0) {
    hash.Add(buffer, static_cast<size_t>(file.gcount()));
    size += static_cast<uint64_t>(file.gcount());
  }
  char text[64];
  std::snprintf(text, sizeof text, "%llu bytes, fnv1a64 %016llx",
                static_cast<unsigned long long>(size), static_cast<unsigned long long>(hash.value));
  return text;
}

// The photo folder as a run setting: its absolute path, and a hash of the
// names and sizes of its files (sorted), so that a changed folder is noticed.
std::string TextureDirSetting(const std::string& dir) {
  if (dir.empty()) return "";
  std::vector<std::pair<std::string, uintmax_t>> files;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir)) {
    if (entry.is_regular_file()) files.emplace_back(entry.path().filename().string(), entry.file_size());
  }
  std::sort(files.begin(), files.end());
  Fnv1a64 hash;
  for (const auto& [name, size] : files) hash.Add(name + "\n" + std::to_string(size) + "\n");
  char text[40];
  std::snprintf(text, sizeof text, " (%zu files, fnv1a64 %016llx)", files.size(),
                static_cast<unsigned long long>(hash.value));
  return AbsolutePathSetting(dir) + text;
}

// The settings that change what a step computes: a checkpoint can only be
// resumed by a run with the same ones (the total step count may differ).
// Computed once per run (they read the init weights and list the photo
// folder), then passed to every checkpoint.
using Settings = std::map<std::string, std::string>;
Settings RunSettings(const TrainOptions& o) {
  std::ostringstream lr, clip, widening;
  lr.precision(17);
  clip.precision(17);
  widening.precision(17);
  lr << o.lr;
  clip << o.grad_clip;
  widening << o.train_widening_max;
  std::ostringstream mvsnet_fraction;
  mvsnet_fraction.precision(17);
  mvsnet_fraction << o.mvsnet_fraction;
  return {{"config", o.config},
          {"height", std::to_string(o.height)},
          {"width", std::to_string(o.width)},
          {"num_sources", std::to_string(o.num_sources)},
          {"batch_size", std::to_string(o.batch_size)},
          {"seed", std::to_string(o.seed)},
          {"lr", lr.str()},
          {"lr_halve_every", std::to_string(o.lr_halve_every)},
          {"lr_warmup_steps", std::to_string(o.lr_warmup_steps)},
          {"grad_clip", clip.str()},
          {"train_widening_max", widening.str()},
          {"mvsnet_root", AbsolutePathSetting(o.mvsnet_root)},
          {"mvsnet_fraction", mvsnet_fraction.str()},
          {"init_weights", InitWeightsSetting(o.init_weights)},
          {"texture_dir", TextureDirSetting(o.texture_dir)},
          {"photo_probability", o.texture_dir.empty() ? "" : std::to_string(o.photo_probability)},
          {"matching_loss_weight", std::to_string(o.matching_loss_weight)},
          {"matching_warmup_steps", std::to_string(o.matching_warmup_steps)},
          {"scene_reuse", std::to_string(o.scene_reuse)},
          {"train_coarse_iterations", std::to_string(o.train_coarse_iterations)},
          {"difficulty_start", std::to_string(o.difficulty_start)},
          {"difficulty_ramp_steps", std::to_string(o.difficulty_ramp_steps)}};
}

// Settings added after checkpoints were first written, with the value that a
// checkpoint without one was trained with, so that such checkpoints resume.
std::optional<std::string> SettingBeforeItExisted(const std::string& key) {
  if (key == "mvsnet_root") return "";
  if (key == "mvsnet_fraction") return "1";
  if (key == "train_widening_max") return "1";
  if (key == "init_weights") return "";
  if (key == "texture_dir" || key == "photo_probability") return "";
  // Model v2's settings: before them, runs trained the paper's design
  // (whose configs ignore the matching loss) on a new scene every step.
  if (key == "matching_loss_weight") return std::to_string(0.5);
  if (key == "matching_warmup_steps") return "0";
  if (key == "scene_reuse") return "1";
  if (key == "train_coarse_iterations") return "0";
  if (key == "difficulty_start") return std::to_string(1.0);
  if (key == "difficulty_ramp_steps") return "0";
  if (key == "lr_warmup_steps") return "0";
  return std::nullopt;
}

// Adam keeps its per-parameter state under the parameter's TensorImpl: its
// address printed to a string in older LibTorch (Debian's 1.13; it used
// c10::guts::to_string, since removed), the address itself (void*) in newer
// ones (PyTorch PR #108480, 2023). The key type comes from the state map, so
// the trainer builds against both: a GPU machine's CUDA PyTorch is newer.
template <typename StateMap>
typename StateMap::key_type AdamStateKey(const StateMap& /*state*/, const torch::Tensor& parameter) {
  using Key = typename StateMap::key_type;
  if constexpr (std::is_same_v<Key, std::string>) {
    std::ostringstream key;  // c10::guts::to_string's format: operator<< of the pointer
    key << static_cast<const void*>(parameter.unsafeGetTensorImpl());
    return key.str();
  } else {
    return static_cast<Key>(parameter.unsafeGetTensorImpl());
  }
}

// Writes checkpoint `step` and then retires the older ones: their weights
// are kept under KeptWeightsPath when their step is a multiple of
// keep_weights_every (> 0), removed otherwise; their optimiser state goes.
void SaveCheckpoint(const fs::path& dir, int64_t step, DispMvsNet& net, const ModelConfig& config,
                    torch::optim::Adam& optimizer, const Settings& settings, int64_t keep_weights_every) {
  model::NamedTensors tensors;
  int64_t adam_step = -1;
  for (const auto& item : net->named_parameters()) {
    auto found = optimizer.state().find(AdamStateKey(optimizer.state(), item.value()));
    if (found == optimizer.state().end()) continue;  // never received a gradient
    auto& state = static_cast<torch::optim::AdamParamState&>(*found->second);
    if (adam_step >= 0 && state.step() != adam_step) {
      throw std::runtime_error("Adam state: parameters at different steps");
    }
    adam_step = state.step();
    tensors.emplace_back("exp_avg/" + item.key(), state.exp_avg());
    tensors.emplace_back("exp_avg_sq/" + item.key(), state.exp_avg_sq());
  }
  if (tensors.size() != 2 * optimizer.state().size()) {
    // Every state belongs to one of the parameters: else AdamStateKey does
    // not match the optimizer's keys, and resuming would silently restart Adam.
    throw std::logic_error("Adam state: " + std::to_string(optimizer.state().size()) + " states, " +
                           std::to_string(tensors.size() / 2) + " found under the parameters' keys");
  }
  Settings metadata = settings;
  metadata["step"] = std::to_string(step);
  metadata["adam_step"] = std::to_string(std::max<int64_t>(adam_step, 0));
  model::SaveSafetensors(OptimPath(dir, step).string(), tensors, metadata);
  model::SaveModuleWeights(*net, config, WeightsPath(dir, step).string());  // marks it complete

  for (int64_t older : CompleteCheckpoints(dir)) {
    if (older >= step) continue;
    if (keep_weights_every > 0 && older % keep_weights_every == 0) {
      fs::rename(WeightsPath(dir, older), KeptWeightsPath(dir, older));
    } else {
      fs::remove(WeightsPath(dir, older));
    }
    fs::remove(OptimPath(dir, older));
  }
}

void LoadCheckpoint(const fs::path& dir, int64_t step, DispMvsNet& net, torch::optim::Adam& optimizer,
                    const Settings& settings, torch::Device device) {
  const std::string optim_path = OptimPath(dir, step).string();
  const auto file = model::LoadSafetensors(optim_path);
  for (const auto& [key, value] : settings) {
    const auto found = file.metadata.find(key);
    const std::optional<std::string> stored =
        found != file.metadata.end() ? std::optional<std::string>(found->second) : SettingBeforeItExisted(key);
    if (!stored || *stored != value) {
      throw std::runtime_error(optim_path + ": checkpoint of a different run (" + key + " is '" +
                               stored.value_or("<missing>") +
                               "', this run has '" + value + "'); use another checkpoint dir");
    }
  }
  const auto step_entry = file.metadata.find("adam_step");
  if (step_entry == file.metadata.end()) throw std::runtime_error(optim_path + ": no adam_step");
  const int64_t adam_step = std::stoll(step_entry->second);

  model::LoadModuleWeights(*net, WeightsPath(dir, step).string());

  std::map<std::string, torch::Tensor> stored(file.tensors.begin(), file.tensors.end());
  optimizer.state().clear();
  for (const auto& item : net->named_parameters()) {
    const auto avg = stored.find("exp_avg/" + item.key());
    const auto avg_sq = stored.find("exp_avg_sq/" + item.key());
    if (avg == stored.end() || avg_sq == stored.end()) continue;
    if (avg->second.sizes() != item.value().sizes() || avg_sq->second.sizes() != item.value().sizes()) {
      throw std::runtime_error(optim_path + ": Adam state of " + item.key() + " has the wrong shape");
    }
    auto state = std::make_unique<torch::optim::AdamParamState>();
    state->step(adam_step);
    state->exp_avg(avg->second.to(device, item.value().scalar_type()));
    state->exp_avg_sq(avg_sq->second.to(device, item.value().scalar_type()));
    optimizer.state()[AdamStateKey(optimizer.state(), item.value())] = std::move(state);
  }
}

// ----------------------------------------------------------------- validation

std::vector<synth::SynthSample> ValidationScenes(const TrainOptions& options, torch::Device device) {
  const auto config = SynthConfigFor(options);
  std::vector<synth::SynthSample> scenes;
  for (int64_t i = 0; i < options.num_validation_scenes; ++i) {
    scenes.push_back(GenerateUsableSample(config, options.validation_seed_base + i, device));
  }
  return scenes;
}

// Coarse matching accuracy on the validation scenes (WideningResult's
// coarse_top1 and matching_count). It does not depend on the depth-range
// hint, so it is measured once per validation, not once per widening.
std::pair<double, double> CoarseMatchingAccuracy(DispMvsNet& net, const std::vector<synth::SynthSample>& scenes) {
  const bool was_training = net->is_training();
  net->eval();
  torch::NoGradGuard no_grad;
  double hits = 0, counted = 0;
  for (const auto& scene : scenes) {
    const auto batch = MakeBatch({scene}, 1.0);
    const model::StageMatching matching = net->CoarseMatching(batch.input);
    const auto truth = model::ComputeGroundTruthMatches(
        batch.gt_depths, batch.input.intrinsics, batch.input.extrinsics, matching.stride,
        matching.logits.size(2), matching.logits.size(3));
    const auto result = model::MatchingLoss(matching, truth);
    hits += result.top1;
    counted += result.count;
  }
  net->train(was_training);
  return {counted > 0 ? hits / counted : 0.0, counted};
}

// The depth metrics of a WideningResult on the validation scenes with the
// hint widened by `widening` (0: no hint), with the network's iterations as
// they are. With `look_from_sources` (the evaluation table; training's
// validations log only the first line) also `seen`, `seen_share` and
// `source_pixels` (source_pixel_metrics.h).
WideningResult ValidateDepth(DispMvsNet& net, const std::vector<synth::SynthSample>& scenes,
                             const TrainOptions& options, double widening, bool look_from_sources) {
  if (widening == 0 && net->config().NeedsDepthRange()) {
    throw std::invalid_argument("weights of config '" + net->config().name +
                                "' need a depth-range hint: no 'none' row for them");
  }
  const bool was_training = net->is_training();
  net->eval();
  torch::NoGradGuard no_grad;
  ValidationDepthSums sums, seen_sums;
  SourcePixelCounts source_sums;
  for (size_t i = 0; i < scenes.size(); ++i) {
    const auto batch = MakeBatch({scenes[i]}, widening);
    // Same initialisation for a scene at every evaluation: the numbers differ
    // between evaluations only because the weights do.
    const auto output = net->forward(batch.input, CpuGenerator(options.validation_seed_base + i));
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

// One table row per widening; the coarse accuracy measured once for all.
std::vector<WideningResult> Validate(DispMvsNet& net, const std::vector<synth::SynthSample>& scenes,
                                     const TrainOptions& options, const std::vector<double>& widenings,
                                     bool look_from_sources) {
  std::vector<WideningResult> results;
  for (double x : widenings) {
    results.push_back(ValidateDepth(net, scenes, options, x, look_from_sources));
  }
  const auto [top1, counted] = CoarseMatchingAccuracy(net, scenes);
  for (auto& row : results) {
    row.coarse_top1 = top1;
    row.matching_count = counted;
  }
  return results;
}

}  // namespace

// ---------------------------------------------------------------- public API

void TrainOptions::Check(bool for_training) const {
  auto fail = [](const std::string& what) { throw std::invalid_argument(what); };
  ModelConfig::ByName(config);
  if (height < 1 || height > 8192) fail("height must be in [1, 8192], got " + std::to_string(height));
  if (width < 1 || width > 8192) fail("width must be in [1, 8192], got " + std::to_string(width));
  if (num_sources < 1 || num_sources > 64) {
    fail("num_sources must be in [1, 64], got " + std::to_string(num_sources));
  }
  if (batch_size < 1 || batch_size > 1024) fail("batch_size must be in [1, 1024], got " + std::to_string(batch_size));
  if (steps < 0 || steps > 999'999'999) fail("steps must be in [0, 999999999], got " + std::to_string(steps));
  if (!(std::isfinite(lr) && lr > 0 && lr < 1)) fail("lr must be in (0, 1), got " + std::to_string(lr));
  if (lr_halve_every < 0) fail("lr_halve_every must be >= 0, got " + std::to_string(lr_halve_every));
  if (lr_warmup_steps < 0) fail("lr_warmup_steps must be >= 0, got " + std::to_string(lr_warmup_steps));
  if (!(std::isfinite(grad_clip) && grad_clip >= 0)) {
    fail("grad_clip must be a finite number >= 0, got " + std::to_string(grad_clip));
  }
  if (!(std::isfinite(train_widening_max) && train_widening_max >= 1 && train_widening_max <= 1000)) {
    fail("train_widening_max must be in [1, 1000], got " + std::to_string(train_widening_max));
  }
  model::ParseDevice(device);  // usable or not: checked when training starts
  if (threads < 0 || threads > 1024) fail("threads must be in [0, 1024], got " + std::to_string(threads));
  if (checkpoint_every < 1) fail("checkpoint_every must be >= 1, got " + std::to_string(checkpoint_every));
  if (keep_weights_every < 0 || keep_weights_every % checkpoint_every != 0) {
    fail("keep_weights_every must be 0 or a multiple of checkpoint_every (" + std::to_string(checkpoint_every) +
         "), got " + std::to_string(keep_weights_every));
  }
  if (validate_every < 0) fail("validate_every must be >= 0, got " + std::to_string(validate_every));
  if (num_validation_scenes < 0 || num_validation_scenes > 100'000) {
    fail("num_validation_scenes must be in [0, 100000], got " + std::to_string(num_validation_scenes));
  }
  if (validation_seed_base >= kTopBit - 100'000) {
    fail("validation_seed_base must be below 2^63 - 100000 (training seeds use the top bit)");
  }
  if (for_training && checkpoint_dir.empty()) fail("checkpoint_dir is required for training");
  if (!(mvsnet_fraction >= 0 && mvsnet_fraction <= 1)) {
    fail("mvsnet_fraction must be in [0, 1], got " + std::to_string(mvsnet_fraction));
  }
  // A fraction of a data set that is not there is a mistake, not a request.
  if (mvsnet_root.empty() && mvsnet_fraction != 1) fail("mvsnet_fraction needs mvsnet_root");
  if (!texture_dir.empty() && !fs::is_directory(texture_dir)) {
    fail("texture_dir: no such folder " + texture_dir);
  }
  if (!(photo_probability >= 0 && photo_probability <= 1)) {
    fail("photo_probability must be in [0, 1], got " + std::to_string(photo_probability));
  }
  if (!init_weights.empty() && !fs::is_regular_file(init_weights)) {
    fail("init_weights: no such file " + init_weights);
  }
  if (!(std::isfinite(matching_loss_weight) && matching_loss_weight >= 0)) {
    fail("matching_loss_weight must be a finite number >= 0, got " + std::to_string(matching_loss_weight));
  }
  if (matching_warmup_steps < 0) {
    fail("matching_warmup_steps must be >= 0, got " + std::to_string(matching_warmup_steps));
  }
  if (matching_warmup_steps > 0 && (matching_loss_weight == 0 || ModelConfig::ByName(config).NeedsDepthRange())) {
    fail("matching_warmup_steps needs a v2 config and matching_loss_weight > 0");
  }
  if (!(difficulty_start >= 0 && difficulty_start <= 1)) {
    fail("difficulty_start must be in [0, 1], got " + std::to_string(difficulty_start));
  }
  if (difficulty_ramp_steps < 0) fail("difficulty_ramp_steps must be >= 0");
  if (train_coarse_iterations < 0 || train_coarse_iterations > 1000) {
    fail("train_coarse_iterations must be in [0, 1000], got " + std::to_string(train_coarse_iterations));
  }
  for (const auto& [name, value] : {std::pair<const char*, int64_t>{"eval_coarse_iterations",
                                                                     eval_coarse_iterations},
                                    {"eval_fine_iterations", eval_fine_iterations}}) {
    if (value < 0 || value > 1000) {
      fail(std::string(name) + " must be in [0, 1000], got " + std::to_string(value));
    }
    if (value > 0 && for_training) fail(std::string(name) + " is for evaluation only");
  }
  try {
    model::ResolvePrecision(precision, torch::kCPU);
  } catch (const std::invalid_argument& error) {
    fail(error.what());
  }
  if (scene_reuse < 1 || scene_reuse > 64) fail("scene_reuse must be in [1, 64], got " + std::to_string(scene_reuse));
  if (!(std::isfinite(max_cpu_minutes) && max_cpu_minutes >= 0)) {
    fail("max_cpu_minutes must be a finite number >= 0, got " + std::to_string(max_cpu_minutes));
  }
  if (!(std::isfinite(max_minutes) && max_minutes >= 0)) {
    fail("max_minutes must be a finite number >= 0, got " + std::to_string(max_minutes));
  }
  SynthConfigFor(*this);  // the generator's own limits
}

double TrainingDifficultyAt(const TrainOptions& options, int64_t step) {
  if (options.difficulty_ramp_steps <= 0 || step >= options.difficulty_ramp_steps) return 1.0;
  const double t = static_cast<double>(step) / static_cast<double>(options.difficulty_ramp_steps);
  return options.difficulty_start + (1.0 - options.difficulty_start) * t;
}

double LearningRateAt(const TrainOptions& options, int64_t step) {
  double lr = options.lr;
  if (options.lr_halve_every > 0) lr *= std::pow(0.5, static_cast<double>(step / options.lr_halve_every));
  if (step < options.lr_warmup_steps) {
    lr *= static_cast<double>(step + 1) / static_cast<double>(options.lr_warmup_steps);
  }
  return lr;
}

uint64_t TrainingSampleSeed(uint64_t seed, int64_t step, int64_t index) {
  return Mix(Mix(seed, static_cast<uint64_t>(step)), static_cast<uint64_t>(index)) | kTopBit;
}

double TrainingWideningAt(const TrainOptions& options, int64_t step) {
  if (options.train_widening_max <= 1.0) return 1.0;
  // 53 random bits -> u in [0, 1).
  const uint64_t bits = Mix(Mix(options.seed, 0x1D3A7Eu), static_cast<uint64_t>(step)) >> 11;
  const double u = static_cast<double>(bits) * (1.0 / 9007199254740992.0);
  return std::exp(u * std::log(options.train_widening_max));
}

std::string FormatMatching(const WideningResult& r) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "coarse top-1: %.4f", r.coarse_top1);
  return buffer;
}

std::string FormatMetrics(const ValidationDepthMetrics& m) {
  char buffer[160];
  std::snprintf(buffer, sizeof buffer, "<1%%: %.4f  <2%%: %.4f  <5%%: %.4f  AbsRel: %.4f  coverage: %.4f",
                m.within_1, m.within_2, m.within_5, m.abs_rel, m.coverage);
  return buffer;
}

std::string FormatSeenMetrics(const WideningResult& r) {
  char share[64];
  std::snprintf(share, sizeof share, "seen by a source (%.4f of the pixels): ", r.seen_share);
  return share + FormatMetrics(r.seen);
}

namespace {

// The weights and Adam moments a run starts from: its last complete
// checkpoint, else --init_weights, else the seeded random ones already in
// `net`. Returns the first step to run.
int64_t RestoreRun(const TrainOptions& options, const fs::path& dir, const Settings& settings,
                   DispMvsNet& net, torch::optim::Adam& optimizer, torch::Device device, Logger& log) {
  const auto checkpoints = CompleteCheckpoints(dir);
  if (!checkpoints.empty()) {
    const int64_t start = checkpoints.back();
    LoadCheckpoint(dir, start, net, optimizer, settings, device);
    log.Line("resumed from " + WeightsPath(dir, start).string() + " at step " + std::to_string(start));
    return start;
  }
  if (!options.init_weights.empty()) {
    // Checked before anything is trained: a mismatch names the tensor.
    model::LoadModuleWeights(*net, options.init_weights);
    log.Line("initialised from " + options.init_weights + " (" + settings.at("init_weights") + ")");
  }
  return 0;
}

// Where the training samples come from: generated scenes (with photo
// textures when the run has a photo folder) and the MVSNet data set, if any.
// Each generated scene serves options.scene_reuse consecutive steps.
class TrainingSamples {
 public:
  TrainingSamples(const TrainOptions& options, torch::Device device, Logger& log)
      : options_(options), device_(device), synth_config_(SynthConfigFor(options)) {
    if (!options.texture_dir.empty()) {
      std::ostringstream warnings;
      synth_config_.photos = std::make_shared<const synth::PhotoSet>(
          synth::LoadPhotoFolder(options.texture_dir, {}, &warnings));
      synth_config_.photo_probability = options.photo_probability;
      std::istringstream lines(warnings.str());
      for (std::string line; std::getline(lines, line);) log.Line(line);
      log.Line("photo textures: " + std::to_string(synth_config_.photos->size()) + " photos from " +
               options.texture_dir + ", probability " + std::to_string(options.photo_probability));
    }
    mvsnet_ = OpenMvsnetSource(options, synth_config_);
    if (mvsnet_) {
      log.Line("MVSNet data set " + options.mvsnet_root + ": " +
               std::to_string(mvsnet_->dataset.scans.size()) + " scans, " +
               std::to_string(mvsnet_->views.size()) + " reference views with ground truth, fraction " +
               std::to_string(options.mvsnet_fraction));
    }
  }

  // The batch's samples of training step `step`: the scenes of its group,
  // each with the step's view as the reference.
  std::vector<synth::SynthSample> ForStep(int64_t step) {
    const int64_t group = step / options_.scene_reuse;
    if (group != cached_group_) {
      synth_config_.difficulty = TrainingDifficultyAt(options_, group * options_.scene_reuse);
      cached_scenes_.clear();
      for (int64_t j = 0; j < options_.batch_size; ++j) {
        cached_scenes_.push_back(TrainingSample(options_, synth_config_, mvsnet_, group, j, device_));
      }
      cached_group_ = group;
    }
    std::vector<synth::SynthSample> samples;
    for (const auto& scene : cached_scenes_) {
      samples.push_back(WithReference(scene, step % options_.scene_reuse));
    }
    return samples;
  }

 private:
  const TrainOptions& options_;
  torch::Device device_;
  synth::SynthConfig synth_config_;
  std::optional<MvsnetSource> mvsnet_;
  int64_t cached_group_ = -1;
  std::vector<synth::SynthSample> cached_scenes_;
};

// The loss of one training step and what the log reports of it.
struct StepLoss {
  torch::Tensor loss;        // what is minimised
  torch::Tensor depth_loss;  // the sequence loss
  double match_loss = 0;     // the matching loss (model v2), 0 without one
  double top1 = 0;           // coarse matches whose arg-max is right, of `counted`
  double counted = 0;
};

StepLoss ComputeStepLoss(const TrainOptions& options, const model::DispMvsOutput& output,
                         const TrainingBatch& batch, double widening, bool matching_loss, int64_t step) {
  StepLoss result;
  // Normalised by the unwidened range (see TrainOptions::train_widening_max).
  result.depth_loss = model::SequenceLoss(output.inv_depths, batch.gt_depth, batch.gt_valid,
                                          batch.input.depth_min * widening, batch.input.depth_max / widening);
  result.loss = result.depth_loss;
  if (!matching_loss) return result;
  torch::Tensor match_loss = torch::zeros({}, result.depth_loss.options());
  for (const auto& stage : output.matching) {
    const auto truth = model::ComputeGroundTruthMatches(batch.gt_depths, batch.input.intrinsics,
                                                        batch.input.extrinsics, stage.stride,
                                                        stage.logits.size(2), stage.logits.size(3));
    const auto stage_result = model::MatchingLoss(stage, truth);
    match_loss = match_loss + stage_result.loss;
    if (stage.stride == model::DispMvsNetImpl::kCoarseStride) {
      result.top1 = stage_result.top1;
      result.counted = stage_result.count;
    }
  }
  result.match_loss = match_loss.item<double>();
  const bool warmup = step < options.matching_warmup_steps;
  // During the warm-up the depth loss enters with weight 0: every
  // parameter still receives a (zero) gradient, so Adam steps them all
  // alike and the checkpoint's single step count stays true.
  result.loss = warmup ? match_loss + 0.0 * result.depth_loss
                       : result.depth_loss + options.matching_loss_weight * match_loss;
  return result;
}

double SecondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

// Where a step's wall time went.
struct StepTimes {
  double total = 0, scenes = 0, forward = 0, backward = 0, cpu = 0;
};

std::string StepLine(const TrainOptions& options, int64_t step, const StepLoss& loss, double lr,
                     const StepTimes& times, double eta_seconds) {
  char line[384];
  std::snprintf(line, sizeof line,
                "step %lld/%lld  loss %.5f  depth %.5f  match %.4f  top1 %.3f  lr %.3e  %.2f s/step "
                "(scenes %.2f, forward %.2f, backward %.2f; cpu %.2f s)  ETA %s",
                static_cast<long long>(step + 1), static_cast<long long>(options.steps),
                loss.loss.item<double>(), loss.depth_loss.item<double>(), loss.match_loss,
                loss.counted > 0 ? loss.top1 / loss.counted : 0.0, lr, times.total, times.scenes,
                times.forward, times.backward, times.cpu, FormatDuration(eta_seconds).c_str());
  return line;
}

// Validation runs the iterations the weights are saved with, then training
// goes on with its own.
void ValidateAndLog(DispMvsNet& net, const ModelConfig& config, const std::vector<synth::SynthSample>& scenes,
                    const TrainOptions& options, int64_t step, double cpu_start, Logger& log) {
  if (scenes.empty()) return;
  net->set_iterations(config.coarse_iterations, config.fine_iterations);
  const model::Precision training_precision = net->precision();
  net->set_precision(model::Precision::kFloat32);
  const WideningResult result = Validate(net, scenes, options, {1.0}, /*look_from_sources=*/false).front();
  net->set_precision(training_precision);
  if (options.train_coarse_iterations > 0) {
    net->set_iterations(options.train_coarse_iterations, config.fine_iterations);
  }
  char cpu[64];
  std::snprintf(cpu, sizeof cpu, "  cpu %.0f s", CpuSeconds() - cpu_start);
  log.Line("validate step " + std::to_string(step) + cpu + "  x=1  " + FormatMetrics(result.metrics) +
           "  " + FormatMatching(result));
}

}  // namespace

void Train(const TrainOptions& options, std::ostream& console) {
  options.Check(/*for_training=*/true);
  const torch::Device device = model::ParseUsableDevice(options.device);
  SetThreads(options.threads);
  const fs::path dir = options.checkpoint_dir;
  fs::create_directories(dir);
  Logger log(console, dir / "train.log");
  if (device.is_cpu()) {
    if (options.low_memory) {
      model::KeepFreedTensorMemory();
      log.Line("CPU memory: freed blocks above 32 MiB returned to the system (--low_memory 1)");
    } else {
      model::KeepAllFreedTensorMemory();
      log.Line("CPU memory: every freed block kept for the next step (--low_memory 1 saves memory)");
    }
  }

  const ModelConfig config = ModelConfig::ByName(options.config);
  torch::manual_seed(options.seed);  // the initial weights
  DispMvsNet net(config);
  net->to(device);
  torch::optim::Adam optimizer(net->parameters(), torch::optim::AdamOptions(options.lr));
  const Settings settings = RunSettings(options);
  const int64_t start = RestoreRun(options, dir, settings, net, optimizer, device, log);

  TrainingSamples training_samples(options, device, log);
  const auto validation_scenes = ValidationScenes(options, device);
  const double cpu_start = CpuSeconds();
  const bool matching_loss = !config.NeedsDepthRange() && options.matching_loss_weight > 0;
  if (options.train_coarse_iterations > 0) {
    net->set_iterations(options.train_coarse_iterations, config.fine_iterations);
  }
  net->train();
  net->set_precision(model::ResolvePrecision(options.precision, device));
  log.Line(std::string("GRU convolutions in ") + model::PrecisionName(net->precision()));
  const auto run_start = std::chrono::steady_clock::now();
  int64_t last_validated = -1;
  int64_t final_step = std::max(start, options.steps);
  for (int64_t step = start; step < options.steps; ++step) {
    const auto step_start = std::chrono::steady_clock::now();
    const double step_cpu_start = CpuSeconds();
    StepTimes times;
    const double lr = LearningRateAt(options, step);
    for (auto& group : optimizer.param_groups()) {
      static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
    }
    const double widening = TrainingWideningAt(options, step);
    const auto batch = MakeBatch(training_samples.ForStep(step), widening);
    times.scenes = SecondsSince(step_start);

    const auto forward_start = std::chrono::steady_clock::now();
    const auto output = net->forward(batch.input, CpuGenerator(TrainingInitSeed(options.seed, step)));
    const StepLoss loss = ComputeStepLoss(options, output, batch, widening, matching_loss, step);
    times.forward = SecondsSince(forward_start);

    const auto backward_start = std::chrono::steady_clock::now();
    optimizer.zero_grad();
    loss.loss.backward();
    if (options.grad_clip > 0) torch::nn::utils::clip_grad_norm_(net->parameters(), options.grad_clip);
    optimizer.step();
    times.backward = SecondsSince(backward_start);

    times.total = SecondsSince(step_start);
    times.cpu = CpuSeconds() - step_cpu_start;
    const double mean_seconds = SecondsSince(run_start) / static_cast<double>(step + 1 - start);
    log.Line(StepLine(options, step, loss, lr, times, mean_seconds * static_cast<double>(options.steps - step - 1)));

    const int64_t done = step + 1;
    const bool out_of_cpu_time =
        options.max_cpu_minutes > 0 && CpuSeconds() - cpu_start >= 60.0 * options.max_cpu_minutes;
    const bool out_of_wall_time = options.max_minutes > 0 && SecondsSince(run_start) >= 60.0 * options.max_minutes;
    const bool out_of_time = out_of_cpu_time || out_of_wall_time;
    if (done % options.checkpoint_every == 0 || done == options.steps || out_of_time) {
      SaveCheckpoint(dir, done, net, config, optimizer, settings, options.keep_weights_every);
    }
    if (options.validate_every > 0 && done % options.validate_every == 0) {
      ValidateAndLog(net, config, validation_scenes, options, done, cpu_start, log);
      last_validated = done;
    }
    if (out_of_time) {
      log.Line("stopping after step " + std::to_string(done) + ": " +
               (out_of_cpu_time ? "--max_cpu_minutes" : "--max_minutes") + " reached");
      final_step = done;
      break;
    }
  }
  if (last_validated != final_step) {
    ValidateAndLog(net, config, validation_scenes, options, final_step, cpu_start, log);
  }
  model::SaveModuleWeights(*net, config, (dir / "model.safetensors").string());
  log.Line("wrote " + (dir / "model.safetensors").string());
}

std::vector<WideningResult> EvaluateWeights(const std::string& weights_path, const TrainOptions& options,
                                            const std::vector<double>& widenings) {
  options.Check(/*for_training=*/false);
  const torch::Device device = model::ParseUsableDevice(options.device);
  if (options.num_validation_scenes < 1) throw std::invalid_argument("num_validation_scenes must be >= 1");
  SetThreads(options.threads);
  if (device.is_cpu()) model::KeepFreedTensorMemory();
  const ModelConfig config = model::ReadModelConfig(weights_path);
  DispMvsNet net(config);
  model::LoadModuleWeights(*net, weights_path);
  net->set_iterations(
      options.eval_coarse_iterations > 0 ? options.eval_coarse_iterations : config.coarse_iterations,
      options.eval_fine_iterations > 0 ? options.eval_fine_iterations : config.fine_iterations);
  net->set_precision(model::ResolvePrecision(options.precision, device));
  net->to(device);
  const auto scenes = ValidationScenes(options, device);
  return Validate(net, scenes, options, widenings, /*look_from_sources=*/true);
}

}  // namespace dispmvs::train
